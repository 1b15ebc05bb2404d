// The car's eye: plays the racing car's camera (the live server's MJPEG, multipart/x-mixed-replace) in the page's
// <figure data-car-eye="URL">. It reads the stream with fetch, so it knows when frames stop: the figure is shown only
// while frames arrive and hidden (nothing, no error) when none came for STALL_MS, when no car races (204), or when the
// live server is away; it then asks again every RETRY_MS. Latest frame wins: while one frame decodes, only the newest
// that arrives meanwhile is kept. Each painted frame counts in data-frames, and data-delay-ms is how long after the
// car took it (its X-Timestamp) it was painted.
(function () {
  "use strict";
  var STALL_MS = 2000;
  var RETRY_MS = 3000;
  var CRLF2 = [13, 10, 13, 10];
  var MAX_HEAD = 4096;          // a part header is a few lines; more without one is not MJPEG
  var MAX_PART = 4 << 20;       // the largest JPEG part taken

  function indexOf(bytes, pattern, from) {
    outer: for (var i = from; i <= bytes.length - pattern.length; i++) {
      for (var j = 0; j < pattern.length; j++) {
        if (bytes[i + j] !== pattern[j]) { continue outer; }
      }
      return i;
    }
    return -1;
  }
  function ascii(text) {
    var out = new Uint8Array(text.length);
    for (var i = 0; i < text.length; i++) { out[i] = text.charCodeAt(i); }
    return out;
  }
  function headers(bytes) {
    var fields = {};
    String.fromCharCode.apply(null, bytes).split("\r\n").forEach(function (line) {
      var colon = line.indexOf(":");
      if (colon > 0) { fields[line.slice(0, colon).trim().toLowerCase()] = line.slice(colon + 1).trim(); }
    });
    return fields;
  }

  // The stream's parts, chunk by chunk, without rescanning or re-copying what came before: only a part's few header
  // bytes are searched (bytes that are not a part header are dropped a few KB at a time until one comes); its JPEG is
  // copied once into a buffer of its Content-Length. Returns false for a part without a usable length.
  function partReader(marker, onFrame) {
    var head = new Uint8Array(0);  // the bytes since the last JPEG, until a whole part header has arrived
    var body = null;               // the JPEG being filled, with its timestamp
    var filled = 0;
    return function (chunk) {
      var at = 0;
      while (at < chunk.length) {
        if (body) {
          var take = Math.min(body.jpeg.length - filled, chunk.length - at);
          body.jpeg.set(chunk.subarray(at, at + take), filled);
          filled += take; at += take;
          if (filled === body.jpeg.length) { onFrame(body); body = null; }
          continue;
        }
        var piece = chunk.subarray(at, Math.min(chunk.length, at + MAX_HEAD));
        var joined = new Uint8Array(head.length + piece.length);
        joined.set(head); joined.set(piece, head.length);
        var start = indexOf(joined, marker, 0);
        var headEnd = start < 0 ? -1 : indexOf(joined, CRLF2, start);
        if (headEnd < 0) {
          head = joined.length > MAX_HEAD ? joined.slice(joined.length - MAX_HEAD) : joined;
          at += piece.length;
          continue;
        }
        var fields = headers(joined.subarray(start + marker.length, headEnd));
        var length = Number(fields["content-length"]);
        if (!(length > 0 && length <= MAX_PART)) { return false; }
        var stamp = Number(fields["x-timestamp"]);
        body = { jpeg: new Uint8Array(length), takenMs: stamp > 0 ? stamp * 1000 : 0 };
        filled = 0;
        at += headEnd + 4 - head.length;  // where the JPEG starts in this chunk
        head = new Uint8Array(0);
      }
      return true;
    };
  }

  function play(figure) {
    var img = figure.querySelector("img");
    var url = figure.dataset.carEye;
    var frames = 0;
    var lastPaint = 0;
    var decoding = false;
    var waiting = null;  // the newest frame that arrived while another decoded
    var stream = 0;      // which connection is current: a frame still decoding when its stream ended shows nothing
    figure.dataset.frames = "0";

    setInterval(function () {
      if (!figure.hidden && performance.now() - lastPaint > STALL_MS) { figure.hidden = true; }
    }, 500);

    // Each frame decodes in an image of its own, off screen, and replaces the shown one whole only once decoded: the
    // figure never shows a half-loaded or empty picture between two frames.
    function paint(frame) {
      if (decoding) { waiting = frame; return; }
      decoding = true;
      var next = new Image(Number(img.getAttribute("width")) || undefined, Number(img.getAttribute("height")) || undefined);
      next.alt = img.alt;
      next.src = URL.createObjectURL(new Blob([frame.jpeg], { type: "image/jpeg" }));
      function finished() {
        decoding = false;
        if (waiting) { var newest = waiting; waiting = null; paint(newest); }
      }
      next.decode().then(function () {
        requestAnimationFrame(function () {
          var shown = img;
          shown.replaceWith(next);
          img = next;
          if (shown.src.indexOf("blob:") === 0) { URL.revokeObjectURL(shown.src); }
          frames += 1;
          lastPaint = performance.now();
          figure.dataset.frames = String(frames);
          if (frame.takenMs > 0) { figure.dataset.delayMs = String(Math.round(Date.now() - frame.takenMs)); }
          if (frame.stream === stream) { figure.hidden = false; }
          finished();
        });
      }, function () {  // a frame that does not decode is skipped
        URL.revokeObjectURL(next.src);
        finished();
      });
    }

    function ended() { stream += 1; figure.hidden = true; again(); }
    function again() { setTimeout(connect, RETRY_MS); }

    function connect() {
      fetch(url, { cache: "no-store", credentials: "omit" }).then(function (response) {
        var type = response.headers.get("Content-Type") || "";
        var boundary = (type.split("boundary=")[1] || "").replace(/"/g, "").trim();
        if (response.status !== 200 || !response.body || !boundary) { again(); return; }
        var current = stream;
        var parts = partReader(ascii("--" + boundary.replace(/^--/, "")), function (frame) {
          frame.stream = current;
          paint(frame);
        });
        var reader = response.body.getReader();
        function pump() {
          return reader.read().then(function (step) {
            if (step.done) { ended(); return; }
            if (!parts(step.value)) { reader.cancel(); ended(); return; }
            return pump();
          });
        }
        return pump();
      }).catch(ended);
    }
    connect();
  }

  function start() { document.querySelectorAll("[data-car-eye]").forEach(play); }
  if (document.readyState === "loading") { document.addEventListener("DOMContentLoaded", start); } else { start(); }
})();
