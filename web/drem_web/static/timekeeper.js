// Timekeeper screen: keyboard shortcuts, and time-left / current-lap ticking between the server's state polls.
// The server owns the race; every poll (about once a second) re-syncs the displays from its numbers.
(function () {
  "use strict";

  // Error answers (bad input, a rule refusing a command) carry the screen with the message: show them.
  if (window.htmx) {
    htmx.config.responseHandling = [
      { code: "204", swap: false },
      { code: "[23]..", swap: true },
      { code: "4..", swap: true, error: false },
      { code: "...", swap: false, error: true },
    ];
  }

  var synced = { at: performance.now(), timeLeft: 0, currentLap: 0, running: false };

  function clockText(ms) {
    ms = Math.max(0, Math.floor(ms));
    var minutes = Math.floor(ms / 60000);
    var seconds = Math.floor(ms / 1000) % 60;
    var millis = ms % 1000;
    return minutes + ":" + String(seconds).padStart(2, "0") + "." + String(millis).padStart(3, "0");
  }

  function sync() {
    var state = document.getElementById("tk-state");
    if (!state || !state.dataset.raceId) {
      synced.running = false;
      return;
    }
    synced = {
      at: performance.now(),
      timeLeft: Number(state.dataset.timeLeftMs || 0),
      currentLap: Number(state.dataset.currentLapMs || 0),
      running: state.dataset.running === "true",
    };
  }

  function tick() {
    if (!synced.running) return;
    var elapsed = performance.now() - synced.at;
    var timeLeft = document.getElementById("tk-time-left");
    var currentLap = document.getElementById("tk-current-lap");
    if (timeLeft) timeLeft.textContent = clockText(synced.timeLeft - elapsed);
    if (currentLap) currentLap.textContent = clockText(synced.currentLap + elapsed);
  }

  // key → data-shortcut token on a button
  function shortcutFor(event) {
    if (event.ctrlKey || event.metaKey || event.altKey) return null;
    if (event.key === " " || event.code === "Space") return "space";
    if (event.key === "Enter") return "enter";
    if (event.key === "R") return "R";
    if (event.key.length === 1) return event.key.toLowerCase();
    return null;
  }

  // Straight through htmx.ajax rather than .click(): a key pressed right after a swap must not be lost while htmx
  // is still wiring up the new buttons.
  function press(button) {
    // A destructive key asks first, as its button does: htmx.ajax honours the source button's hx-confirm.
    htmx.ajax("POST", button.getAttribute("hx-post"), {
      source: button, target: "#tk-state", swap: "outerHTML",
      values: JSON.parse(button.getAttribute("hx-vals") || "{}"),
    });
  }

  function onKey(event) {
    var target = event.target;
    var tag = target && target.tagName;
    if (tag === "INPUT" || tag === "SELECT" || tag === "TEXTAREA" || (target && target.isContentEditable)) return;
    var token = shortcutFor(event);
    if (!token) return;
    var buttons = document.querySelectorAll("#tk-state [data-shortcut]");
    for (var i = 0; i < buttons.length; i++) {
      var tokens = buttons[i].dataset.shortcut.split(" ");
      if (tokens.indexOf(token) !== -1) {
        // Also stops a focused button from being "clicked" a second time by Space/Enter.
        event.preventDefault();
        if (!buttons[i].disabled) press(buttons[i]);
        return;
      }
    }
  }

  document.addEventListener("keydown", onKey);
  document.addEventListener("htmx:afterSettle", sync);
  document.addEventListener("DOMContentLoaded", sync);
  sync();
  setInterval(tick, 50);
})();
