"""Identity and access: JWT verification, principals, sessions, CSRF and the route access declarations."""
