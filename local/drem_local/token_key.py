"""The per-installation token signing key of a local stack.

moto signs every user pool's tokens with one RSA key that ships inside the moto package
(moto/cognitoidp/resources/jwks-private.json, loaded in moto/cognitoidp/models.py `CognitoIdpUserPool.__init__`), so
anyone with moto installed can mint a token for any local pool. Instead, the first `drem up` generates a key of its
own: a private JWK in `<state-dir>/token-signing-key.json`, mode 0600, kept across restarts. The durable server
signs with it (drem_local.durable.token_signing) and the app verifies local tokens against it alone
(chalicelib.auth.tokens). It is never exported: tokens do not travel with an event, people sign in again.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from drem_infra.resources import TOKEN_SIGNING_KEY_FILE

KEY_BITS = 2048


def key_path(state_dir: Path) -> Path:
    return Path(state_dir) / TOKEN_SIGNING_KEY_FILE


def ensure_signing_key(state_dir: Path) -> dict[str, Any]:
    """The installation's private JWK (with its `kid`), generated and written 0600 if there is none yet."""
    path = key_path(state_dir)
    if not path.exists():
        _create(path)
    jwk = json.loads(path.read_text())
    if jwk.get("kty") != "RSA" or not jwk.get("d") or not jwk.get("kid"):
        raise ValueError(f"{path} is not an RSA private key drem wrote; move it away and start again")
    return jwk


def public_jwk(private: dict[str, Any]) -> dict[str, Any]:
    return {"kty": "RSA", "alg": "RS256", "use": "sig", "kid": private["kid"], "n": private["n"], "e": private["e"]}


def _create(path: Path) -> None:
    from joserfc.jwk import RSAKey

    key = RSAKey.generate_key(KEY_BITS, private=True)
    jwk = {**key.as_dict(private=True), "kid": key.thumbprint(), "alg": "RS256", "use": "sig"}
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    # 0600 from the first byte (no window where another user could read it), then an atomic rename; if two
    # processes race, one rename wins and both read the same file afterwards.
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as handle:
        json.dump(jwk, handle)
        handle.flush()
        os.fsync(handle.fileno())
    try:
        os.link(tmp, path)  # never replaces a key another process wrote meanwhile
    except FileExistsError:
        pass
    finally:
        os.unlink(tmp)
