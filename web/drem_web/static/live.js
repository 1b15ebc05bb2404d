// drem live pages: clocks tick locally between polls, and a new or improved board row is highlighted and scrolled
// into view (after the race summary the server holds on screen, if any). The server re-syncs the clocks whenever the race changes (each swapped fragment carries fresh readings).
// A fragment may have been built (and cached on the server) a while before this poll got it: its clocks carry the
// server time they were read at (data-clock-at) and the response the server time it was sent (X-Drem-Server-Ms), so a
// running clock starts from its reading plus the difference. Each clock element is anchored once, when it arrives.
(function () {
  "use strict";
  var HIGHLIGHT_MS = 12000;
  var clocks = [];
  var previousTimes = null;
  var highlightUntil = {};
  var summarised = {};  // racers whose race summary held the screen: highlighted when the rows come back
  // Big-screen paging: when the rows do not fit the screen, show them a page at a time (every racer appears).
  var DEFAULT_PAGE_MS = 8000;
  var pageIndex = 0;
  var pageShownAt = 0;

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

  function serverTime(xhr) {
    var sent = xhr ? Number(xhr.getResponseHeader("X-Drem-Server-Ms")) : NaN;
    return isFinite(sent) && sent > 0 ? sent : null;
  }
  function anchorClocks(sentAt) {
    var now = performance.now();
    document.querySelectorAll("[data-clock]").forEach(function (el) {
      if (el.dremClock) { return; }
      var running = el.dataset.running === "true";
      var readAt = Number(el.dataset.clockAt);
      var age = running && sentAt !== null && isFinite(readAt) ? Math.max(0, sentAt - readAt) : 0;
      var down = el.dataset.clock === "down";
      el.dremClock = { base: Number(el.dataset.clockMs) + (down ? -age : age), at: now, running: running,
                       down: down };
    });
    clocks = Array.prototype.filter.call(document.querySelectorAll("[data-clock]"), function (el) {
      return el.dremClock;
    }).map(function (el) { return { el: el, clock: el.dremClock }; });
  }
  function tick() {
    var now = performance.now();
    clocks.forEach(function (entry) {
      var clock = entry.clock;
      if (!clock.running || !entry.el.isConnected) { return; }
      var elapsed = now - clock.at;
      entry.el.textContent = clock.down ? countdown(clock.base - elapsed) : lapTime(clock.base + elapsed);
    });
  }

  function boardTimes(board) {
    var times = {};
    board.querySelectorAll(".board-row[data-racer]").forEach(function (row) { times[row.dataset.racer] = row.dataset.time; });
    return times;
  }
  function markChangedRows() {
    var board = document.querySelector("[data-board]");
    // While a race summary holds the screen the rows are hidden: compare them once they are back, so the new result
    // (and the summarised racer's row) is highlighted, and its page shown, when people can see it.
    if (!board) { return; }
    var summaries = board.querySelectorAll("[data-race-summary]");
    if (summaries.length) {
      summaries.forEach(function (summary) { summarised[summary.dataset.racer] = true; });
      return;
    }
    var times = boardTimes(board);
    var now = Date.now();
    var first = null;
    board.querySelectorAll(".board-row[data-racer]").forEach(function (row) {
      var racer = row.dataset.racer;
      var changed = previousTimes !== null && row.dataset.time && previousTimes[racer] !== row.dataset.time;
      if (changed || summarised[racer]) {
        highlightUntil[racer] = now + HIGHLIGHT_MS;
        first = first || row;
      }
      if ((highlightUntil[racer] || 0) > now) { row.classList.add("is-new"); }
    });
    previousTimes = times;
    summarised = {};
    if (first && board.dataset.scroll === "true") {
      var rowsPerPage = layoutPages(board);
      if (rowsPerPage) {  // dwell on the page with the new result
        pageIndex = Math.floor(rowIndex(board, first) / rowsPerPage);
        pageShownAt = Date.now() + pageMs(board);
        showPage(board, rowsPerPage);
      } else {
        first.scrollIntoView({ block: "center", behavior: "smooth" });
      }
    }
  }

  function pageMs(board) {
    var ms = Number(board.dataset.pageMs);
    return isFinite(ms) && ms >= 1000 ? ms : DEFAULT_PAGE_MS;
  }
  function boardRows(board) { return Array.prototype.slice.call(board.querySelectorAll(".board-row")); }
  function rowIndex(board, row) { return boardRows(board).indexOf(row); }
  // Rows per page when the list overflows its box (the big-screen layout gives it a fixed height), else 0.
  function layoutPages(board) {
    var list = board.querySelector(".board-rows");
    var rows = boardRows(board);
    rows.forEach(function (row) { row.hidden = false; });
    if (!list || rows.length < 2 || list.scrollHeight <= list.clientHeight + 1) { return 0; }
    var first = rows[0].getBoundingClientRect();
    var last = rows[rows.length - 1].getBoundingClientRect();
    var pitch = (last.bottom - first.top) / rows.length;
    // A spare row of margin: podium rows are taller, and a half-shown row is no use to anyone 5 m away.
    return Math.max(1, Math.floor(list.clientHeight / pitch) - 1);
  }
  function showPage(board, rowsPerPage) {
    var rows = boardRows(board);
    var pages = Math.ceil(rows.length / rowsPerPage);
    pageIndex = pageIndex % pages;
    rows.forEach(function (row, index) { row.hidden = Math.floor(index / rowsPerPage) !== pageIndex; });
    var label = document.querySelector("[data-board-page]");
    if (label) { label.hidden = false; label.textContent = (pageIndex + 1) + " / " + pages; }
  }
  function paginate(advance) {
    var board = document.querySelector("[data-board]");
    if (!board) { return; }
    var rowsPerPage = layoutPages(board);
    var label = document.querySelector("[data-board-page]");
    if (!rowsPerPage) { pageIndex = 0; if (label) { label.hidden = true; } return; }
    if (advance && Date.now() - pageShownAt >= pageMs(board)) { pageIndex += 1; pageShownAt = Date.now(); }
    showPage(board, rowsPerPage);
  }
  function expireHighlights() {
    var now = Date.now();
    document.querySelectorAll("[data-board] .is-new").forEach(function (row) {
      if ((highlightUntil[row.dataset.racer] || 0) <= now) { row.classList.remove("is-new"); }
    });
  }

  function arrived(event) {
    anchorClocks(serverTime(event && event.detail ? event.detail.xhr : null));
    tick();
  }
  function start() {
    if (window.dremLive) { return; }  // loaded twice (a page swapped in by htmx): one set of timers is enough
    window.dremLive = true;
    arrived(null);
    markChangedRows();
    document.body.addEventListener("htmx:afterSwap", arrived);
    pageShownAt = Date.now();
    paginate(false);
    document.body.addEventListener("htmx:afterSettle", function () {
      anchorClocks(null); paginate(false); markChangedRows();
    });
    window.addEventListener("resize", function () { paginate(false); });
    setInterval(function () { paginate(true); }, 250);
    setInterval(tick, 50);
    setInterval(expireHighlights, 1000);
  }
  if (document.readyState === "loading") { document.addEventListener("DOMContentLoaded", start); } else { start(); }
}());
