// drem live pages: clocks tick locally between polls, and a new or improved board row is highlighted and scrolled
// into view. The server re-syncs the clocks whenever the race changes (each swapped fragment carries fresh readings).
(function () {
  "use strict";
  var HIGHLIGHT_MS = 12000;
  var clocks = [];
  var previousTimes = null;
  var highlightUntil = {};

  function pad(value, width) { return String(value).padStart(width, "0"); }
  function countdown(ms) {
    var seconds = Math.ceil(Math.max(0, ms) / 1000);
    return Math.floor(seconds / 60) + ":" + pad(seconds % 60, 2);
  }
  function lapTime(ms) {
    ms = Math.max(0, Math.floor(ms));
    var rest = ms % 60000;
    return Math.floor(ms / 60000) + ":" + pad(Math.floor(rest / 1000), 2) + "." + pad(rest % 1000, 3);
  }

  function startClocks() {
    var now = performance.now();
    clocks = Array.prototype.map.call(document.querySelectorAll("[data-clock]"), function (el) {
      return { el: el, base: Number(el.dataset.clockMs), at: now, running: el.dataset.running === "true",
               down: el.dataset.clock === "down" };
    });
  }
  function tick() {
    var now = performance.now();
    clocks.forEach(function (clock) {
      if (!clock.running || !clock.el.isConnected) { return; }
      var elapsed = now - clock.at;
      clock.el.textContent = clock.down ? countdown(clock.base - elapsed) : lapTime(clock.base + elapsed);
    });
  }

  function boardTimes(board) {
    var times = {};
    board.querySelectorAll("[data-racer]").forEach(function (row) { times[row.dataset.racer] = row.dataset.time; });
    return times;
  }
  function markChangedRows() {
    var board = document.querySelector("[data-board]");
    if (!board) { return; }
    var times = boardTimes(board);
    var now = Date.now();
    var first = null;
    board.querySelectorAll("[data-racer]").forEach(function (row) {
      var racer = row.dataset.racer;
      if (previousTimes !== null && row.dataset.time && previousTimes[racer] !== row.dataset.time) {
        highlightUntil[racer] = now + HIGHLIGHT_MS;
        first = first || row;
      }
      if ((highlightUntil[racer] || 0) > now) { row.classList.add("is-new"); }
    });
    previousTimes = times;
    if (first && board.dataset.scroll === "true") { first.scrollIntoView({ block: "center", behavior: "smooth" }); }
  }
  function expireHighlights() {
    var now = Date.now();
    document.querySelectorAll("[data-board] .is-new").forEach(function (row) {
      if ((highlightUntil[row.dataset.racer] || 0) <= now) { row.classList.remove("is-new"); }
    });
  }

  function refresh() { startClocks(); markChangedRows(); }
  function start() {
    if (window.dremLive) { return; }  // loaded twice (a page swapped in by htmx): one set of timers is enough
    window.dremLive = true;
    refresh();
    document.body.addEventListener("htmx:afterSettle", refresh);
    setInterval(tick, 50);
    setInterval(expireHighlights, 1000);
  }
  if (document.readyState === "loading") { document.addEventListener("DOMContentLoaded", start); } else { start(); }
}());
