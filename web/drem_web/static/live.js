// drem live pages: clocks tick locally between polls, and a new or improved board row is highlighted and scrolled
// into view (after the race summary the server holds on screen, if any). The server re-syncs the clocks whenever the race changes (each swapped fragment carries fresh readings).
// A fragment may have been built (and cached on the server) a while before this poll got it: its clocks carry the
// server time they were read at (data-clock-at) and the response the server time it was sent (X-Drem-Server-Ms), so a
// running clock starts from its reading plus the difference. Each clock element is anchored once, when it arrives.
// Push: when the page names a live server stream (data-live-stream), the live region subscribes to it (EventSource,
// one fragment per change) and its htmx polls are cancelled while the stream is up; when the stream fails the polls
// run again. Either way a fragment older than the one shown is never swapped in: version tokens are ordered (groups
// of "-"-joined integers separated by "."; see chalicelib/views/live_regions.py, token_is_newer).
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

  // --- version tokens: the same rule as live_regions.token_is_newer ---
  function tokenOrder(token) {
    var groups = String(token).split(".").map(function (group) {
      return group.split("-").map(function (part) { return /^\d+$/.test(part) ? Number(part) : NaN; });
    });
    return groups.some(function (g) { return g.some(isNaN); }) ? null : groups;
  }
  function compareGroup(a, b) {
    for (var i = 0; i < a.length; i += 1) { if (a[i] !== b[i]) { return a[i] > b[i] ? 1 : -1; } }
    return 0;
  }
  function tokenIsNewer(candidate, shown) {
    if (!shown) { return true; }
    var fresh = tokenOrder(candidate), old = tokenOrder(shown);
    if (!fresh || !old || fresh.length !== old.length || fresh.some(function (g, i) { return g.length !== old[i].length; })) {
      return candidate !== shown;
    }
    var forward = false;
    for (var i = 0; i < fresh.length; i += 1) {
      var order = compareGroup(fresh[i], old[i]);
      if (order < 0) { return false; }
      if (order > 0) { forward = true; }
    }
    return forward;
  }
  function fragmentToken(html) {
    var found = /data-version="([^"]*)"/.exec(html || "");
    return found ? found[1] : null;
  }
  function liveRegion() { return document.querySelector("[data-version]"); }
  window.dremTokenIsNewer = tokenIsNewer;  // the browser tests check the rule against the server's

  // A poll's answer (on AWS from any Lambda instance, whose cache may be older) is refused when it is not newer.
  function guardPoll(event) {
    var region = liveRegion();
    var xhr = event.detail && event.detail.xhr;
    if (!region || !xhr || event.detail.target !== region || xhr.status !== 200) { return; }
    var token = fragmentToken(xhr.responseText);
    if (token !== null && !tokenIsNewer(token, region.dataset.version)) { event.detail.shouldSwap = false; }
  }

  // --- push: the live server's event stream ---
  var streaming = false;
  var pushedAt = null;  // the server time the stream's first fragment was sent (an older, cached build)
  function subscribe() {
    var holder = document.querySelector("[data-live-stream]");
    var url = holder ? holder.dataset.liveStream : "";
    if (!url || !window.EventSource || !window.htmx) { return; }
    var source = new EventSource(url);
    source.addEventListener("open", function () { streaming = true; });
    source.addEventListener("clock", function (message) { pushedAt = Number(message.data) || null; });
    source.addEventListener("fragment", function (message) {
      streaming = true;
      var region = liveRegion();
      var token = message.lastEventId || fragmentToken(message.data);
      var sameRegion = region && message.data.indexOf('id="' + region.id + '"') !== -1;
      if (!sameRegion || !tokenIsNewer(token, region.dataset.version)) { pushedAt = null; return; }
      window.htmx.swap(region, message.data, { swapStyle: "outerHTML", swapDelay: 0, settleDelay: 0 },
                       { eventInfo: { dremPushedAt: pushedAt } });
      pushedAt = null;
    });
    source.addEventListener("error", function () {
      // The htmx polls run again until the stream is back: EventSource reconnects by itself (sending the last token
      // as Last-Event-ID) unless the server refused it (503 when full, not an event stream), then polls stay on.
      streaming = false;
    });
    window.dremLiveStream = source;
  }
  function holdPollWhileStreaming(event) {
    var region = liveRegion();
    if (streaming && region && event.detail && event.detail.elt === region) { event.preventDefault(); }
  }

  function arrived(event) {
    var detail = event && event.detail ? event.detail : {};
    anchorClocks(detail.dremPushedAt || serverTime(detail.xhr || null));
    tick();
  }
  function start() {
    if (window.dremLive) { return; }  // loaded twice (a page swapped in by htmx): one set of timers is enough
    window.dremLive = true;
    arrived(null);
    markChangedRows();
    document.body.addEventListener("htmx:afterSwap", arrived);
    document.body.addEventListener("htmx:beforeSwap", guardPoll);
    document.body.addEventListener("htmx:beforeRequest", holdPollWhileStreaming);
    subscribe();
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
