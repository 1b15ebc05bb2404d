// The learning booth's drive page: read the driver's keys, gamepad or touch buttons and send one control per
// decision (15 a second) to the server, which steps the simulator and answers the next camera frame.
(function () {
  "use strict";
  const page = document.querySelector("[data-testid=booth-drive]");
  if (!page) { return; }
  const TICK_MS = 1000 / 15;
  const keys = new Set();
  const touch = new Set();
  const frame = document.getElementById("drive-frame");
  const status = document.getElementById("drive-status");
  const startButton = document.getElementById("drive-start");
  const finishButton = document.getElementById("drive-finish");
  let runId = null;
  let driving = false;
  let stepping = Promise.resolve();  // the decision in flight: Finish waits for it (one sent after would find no drive)

  function csrfToken() {
    try { return JSON.parse(document.body.getAttribute("hx-headers") || "{}")["X-CSRF-Token"] || ""; }
    catch (error) { return ""; }
  }

  async function post(url, body) {
    const response = await fetch(window.dremUrl(url), {  // under the base path the site lives at
      method: "POST", credentials: "same-origin", body: JSON.stringify(body || {}),
      headers: { "Content-Type": "application/json", "Accept": "application/json", "X-CSRF-Token": csrfToken() },
    });
    const answer = await response.json().catch(() => ({}));
    if (!response.ok) { throw new Error((answer.error && answer.error.message) || ("HTTP " + response.status)); }
    return answer;
  }

  function pad() {
    const pads = navigator.getGamepads ? Array.from(navigator.getGamepads()).filter(Boolean) : [];
    if (!pads.length) { return null; }
    const p = pads[0];
    const trigger = (i) => (p.buttons[i] ? p.buttons[i].value : 0);
    return { steering: -(p.axes[0] || 0), throttle: Math.max(trigger(7), -(p.axes[3] || 0)) - trigger(6) };
  }

  function control() {
    const held = (...names) => names.some((n) => keys.has(n));
    let steering = (held("ArrowLeft", "a", "A") || touch.has("left") ? 1 : 0)
      - (held("ArrowRight", "d", "D") || touch.has("right") ? 1 : 0);
    let throttle = (held("ArrowUp", "w", "W") || touch.has("throttle") ? 1 : 0)
      - (held("ArrowDown", "s", "S") || touch.has("brake") ? 1 : 0);
    const stick = pad();
    if (stick && steering === 0 && throttle === 0) { steering = stick.steering; throttle = stick.throttle; }
    const clip = (v) => Math.max(-1, Math.min(1, Math.abs(v) < 0.08 ? 0 : v));
    return { steering: clip(steering), throttle: clip(throttle) };
  }

  // The top-down map (server-built SVG, chalicelib/views/track_map.py): move the car, extend its trail, and mark
  // where it left the track. Coordinates are the simulator's metres; the SVG flips y itself.
  const mapTrail = document.querySelector('[data-map="trail"]');
  const mapCar = document.querySelector('[data-map="car"]');
  const mapOff = document.querySelector('[data-map="off"]');
  function showOnMap(state) {
    if (!mapCar || typeof state.x !== "number" || typeof state.y !== "number") { return; }
    const point = state.x + "," + state.y;
    mapTrail.setAttribute("points", (mapTrail.getAttribute("points") + " " + point).trim());
    mapCar.setAttribute("cx", state.x);
    mapCar.setAttribute("cy", state.y);
    if (state.offtrack) {
      const mark = document.createElementNS("http://www.w3.org/2000/svg", "circle");
      mark.setAttribute("cx", state.x);
      mark.setAttribute("cy", state.y);
      mark.setAttribute("r", mapOff.dataset.markRadius);
      mark.setAttribute("class", "map-off");
      mapOff.appendChild(mark);
    }
  }

  function show(state) {
    if (state.frame) { frame.src = state.frame; }
    showOnMap(state);
    // Counted as the saved run's page counts them: whole laps from the line, of the attempts so far.
    document.getElementById("drive-laps").textContent = state.laps_completed + " of " + state.attempts + " attempts";
    document.getElementById("drive-progress").textContent = state.progress + " %";
    document.getElementById("drive-speed").textContent = state.speed + " m/s";
    document.getElementById("drive-frames").textContent = state.frames;
    document.getElementById("drive-resets").textContent = state.resets;
  }

  async function loop() {
    while (driving) {
      const started = performance.now();
      try {
        const step = post("/api/runs/" + runId + "/drive", control());
        stepping = step.catch(() => null);
        show(await step);
      } catch (error) {
        status.textContent = "Driving stopped: " + error.message;
        driving = false;
        break;
      }
      const wait = TICK_MS - (performance.now() - started);
      if (wait > 0) { await new Promise((resolve) => setTimeout(resolve, wait)); }
    }
  }

  startButton.addEventListener("click", async () => {
    startButton.disabled = true;
    status.textContent = "Starting …";
    try {
      const state = await post("/api/drive", { track_id: page.dataset.track });
      runId = state.run_id;
      if (mapTrail) { mapTrail.setAttribute("points", ""); mapOff.replaceChildren(); }  // a new drive, a new trail
      show(state);
      driving = true;
      finishButton.disabled = false;
      status.textContent = "Recording: drive!";
      page.dataset.runId = runId;
      loop();
    } catch (error) {
      status.textContent = "Could not start: " + error.message;
      startButton.disabled = false;
    }
  });

  finishButton.addEventListener("click", async () => {
    driving = false;
    finishButton.disabled = true;
    status.textContent = "Saving the run …";
    try {
      await stepping;
      const answer = await post("/api/runs/" + runId + "/drive/finish");
      window.location.href = window.dremUrl("/booth/runs/" + answer.run.run_id);
    } catch (error) {
      status.textContent = "Could not save: " + error.message;
    }
  });

  document.addEventListener("keydown", (event) => {
    if (["ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", " "].includes(event.key)) { event.preventDefault(); }
    keys.add(event.key);
  });
  document.addEventListener("keyup", (event) => keys.delete(event.key));
  window.addEventListener("blur", () => keys.clear());
  document.querySelectorAll(".drive-touch [data-control]").forEach((button) => {
    const name = button.dataset.control;
    button.addEventListener("pointerdown", (event) => { event.preventDefault(); touch.add(name); });
    ["pointerup", "pointercancel", "pointerleave"].forEach((type) => button.addEventListener(type, () => touch.delete(name)));
  });
})();
