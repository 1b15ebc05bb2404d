// drem model upload: drag-and-drop (or the file input) → ask drem for a presigned POST → send the file straight to
// S3 with XMLHttpRequest (real progress events) → tell drem the upload is complete → refresh the model list.
(function () {
  "use strict";

  var zone = document.getElementById("drop-zone");
  if (!zone) { return; }
  var input = document.getElementById("model-files");
  var list = document.getElementById("upload-list");

  function csrfToken() {
    try { return JSON.parse(document.body.getAttribute("hx-headers") || "{}")["X-CSRF-Token"] || ""; }
    catch (e) { return ""; }
  }

  function apiPost(url, body) {
    return fetch(url, {
      method: "POST", credentials: "same-origin",
      headers: { "Content-Type": "application/json", "Accept": "application/json", "X-CSRF-Token": csrfToken() },
      body: JSON.stringify(body || {})
    }).then(function (response) {
      return response.json().catch(function () { return {}; }).then(function (data) {
        if (!response.ok) {
          var message = (data.error && data.error.message) || ("drem answered " + response.status);
          throw new Error(message);
        }
        return data;
      });
    });
  }

  function sendToStorage(upload, file, progress) {
    return new Promise(function (resolve, reject) {
      var form = new FormData();
      Object.keys(upload.fields).forEach(function (name) { form.append(name, upload.fields[name]); });
      form.append("file", file);  // S3 wants the file last
      var request = new XMLHttpRequest();
      request.open("POST", upload.url);
      request.upload.addEventListener("progress", function (event) {
        if (event.lengthComputable) { progress.max = event.total; progress.value = event.loaded; }
      });
      request.addEventListener("load", function () {
        if (request.status >= 200 && request.status < 300) { progress.value = progress.max; resolve(); }
        else { reject(new Error("storage refused the upload (" + request.status + ")")); }
      });
      request.addEventListener("error", function () { reject(new Error("the upload was interrupted")); });
      request.send(form);
    });
  }

  function refreshRows() {
    if (window.htmx) {
      window.htmx.ajax("GET", zone.dataset.rowsUrl, { target: "#model-rows", swap: "outerHTML" });
    }
  }

  function uploadOne(file) {
    var item = document.createElement("li");
    item.className = "upload-item";
    item.setAttribute("data-testid", "upload-item");
    var label = document.createElement("span");
    label.textContent = file.name + ": ";
    var state = document.createElement("span");
    state.setAttribute("data-testid", "upload-state");
    state.textContent = "starting…";
    var progress = document.createElement("progress");
    progress.max = file.size || 1;
    progress.value = 0;
    item.append(label, state, progress);
    list.append(item);

    var maxBytes = parseInt(zone.dataset.maxBytes || "0", 10);
    if (maxBytes && file.size > maxBytes) {
      state.textContent = "too large (the limit is " + Math.round(maxBytes / 1048576) + " MiB)";
      state.className = "upload-error";
      return Promise.resolve();
    }
    var modelId = null;
    return apiPost(zone.dataset.requestUrl, { filename: file.name })
      .then(function (ticket) {
        modelId = ticket.model.model_id;
        state.textContent = "uploading…";
        refreshRows();
        return sendToStorage(ticket.upload, file, progress);
      })
      .then(function () {
        state.textContent = "checking…";
        return apiPost(zone.dataset.requestUrl + "/" + encodeURIComponent(modelId) + "/complete");
      })
      .then(function (answer) {
        var labels = JSON.parse(zone.dataset.statusLabels || "{}");
        state.textContent = "uploaded: " + (labels[answer.model.status] || answer.model.status.toLowerCase());
        refreshRows();
      })
      .catch(function (error) {
        state.textContent = error.message;
        state.className = "upload-error";
        if (modelId) { refreshRows(); }
      });
  }

  function uploadAll(files) {
    Array.prototype.reduce.call(files, function (previous, file) {
      return previous.then(function () { return uploadOne(file); });
    }, Promise.resolve());
  }

  ["dragenter", "dragover"].forEach(function (name) {
    zone.addEventListener(name, function (event) { event.preventDefault(); zone.classList.add("dragging"); });
  });
  ["dragleave", "drop"].forEach(function (name) {
    zone.addEventListener(name, function (event) { event.preventDefault(); zone.classList.remove("dragging"); });
  });
  zone.addEventListener("drop", function (event) {
    if (event.dataTransfer && event.dataTransfer.files.length) { uploadAll(event.dataTransfer.files); }
  });
  input.addEventListener("change", function () {
    if (input.files.length) { uploadAll(input.files); input.value = ""; }
  });
})();
