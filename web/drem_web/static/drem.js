// Behaviour the templates used to write inline (onclick=..., hx-on=...), attached here instead: the
// Content-Security-Policy allows scripts only from drem's own files (chalicelib/security_headers.py).
//   data-print                 button: print the page
//   data-autosubmit            select: submit its form when the choice changes
//   data-confirm="question"    submit button: ask first, do nothing on Cancel
//   data-refocus-autofocus     htmx target: after each swap, focus its [autofocus] field
(function () {
  "use strict";

  document.addEventListener("click", function (event) {
    var printer = event.target.closest("[data-print]");
    if (printer) {
      window.print();
      return;
    }
    var asking = event.target.closest("[data-confirm]");
    if (asking && !window.confirm(asking.getAttribute("data-confirm"))) {
      event.preventDefault();
    }
  });

  document.addEventListener("change", function (event) {
    if (event.target.matches("select[data-autosubmit]") && event.target.form) {
      event.target.form.submit();
    }
  });

  // htmx puts focus back where it was before the swap; some forms want it on their first field instead.
  document.addEventListener("htmx:afterSettle", function (event) {
    // An outerHTML swap settles on the new element or on its parent, so look both up and down.
    var target = event.target;
    var box = target.closest && target.closest("[data-refocus-autofocus]");
    box = box || (target.querySelector && target.querySelector("[data-refocus-autofocus]"));
    if (box) {
      setTimeout(function () {
        var field = box.querySelector("[autofocus]");
        if (field) {
          field.focus();
        }
      });
    }
  });
})();
