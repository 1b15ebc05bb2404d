// The one way a script builds a URL of drem: dremUrl("/console/events") → "/drem/console/events" when the site is
// served under /drem. The base path comes from <meta name="drem-base"> (rendered per request by the server,
// chalicelib/base_path.py). URLs the scripts read from the page (hx-get, data-*-url) already carry it.
(function () {
  "use strict";
  var meta = document.querySelector('meta[name="drem-base"]');
  var base = meta ? meta.getAttribute("content") || "" : "";
  window.dremUrl = function (path) {
    return path.charAt(0) === "/" && path.charAt(1) !== "/" ? base + path : path;
  };
})();
