// scenebot guide page: click a shot (its card or its frustum) to highlight it on the map,
// with the photo to start from; served by `scenebot guide serve`, take photo uploads and
// mark shots the person cannot take.
(function () {
  "use strict";
  var data = JSON.parse(document.getElementById("guide-data").textContent);

  function select(rank, from) {
    var shot = data.shots[rank];
    if (!shot) return;
    document.body.classList.add("selected");
    document.querySelectorAll("[data-rank]").forEach(function (el) {
      el.classList.toggle("active", Number(el.getAttribute("data-rank")) === rank);
    });
    document.querySelectorAll(".taken").forEach(function (el) {
      el.classList.toggle("ref", Number(el.getAttribute("data-photo")) === shot.from_index);
    });
    if (history.replaceState) history.replaceState(null, "", "#shot-" + rank);
    var target = from === "map" ? document.getElementById("shot-" + rank)
                                : document.getElementById("maps");
    if (target && target.scrollIntoView) target.scrollIntoView({behavior: "smooth", block: "start"});
  }

  document.querySelectorAll(".shot-card, svg.map .shot").forEach(function (el) {
    var rank = Number(el.getAttribute("data-rank"));
    var from = el.classList.contains("shot") ? "map" : "card";
    el.addEventListener("click", function () { select(rank, from); });
    el.addEventListener("keydown", function (ev) {
      if (ev.key === "Enter" || ev.key === " ") { ev.preventDefault(); select(rank, from); }
    });
  });
  var m = /^#shot-(\d+)$/.exec(location.hash);
  if (m) select(Number(m[1]), "map");

  // uploads: only when served over HTTP by `scenebot guide serve` (not from file://)
  if (!/^https?:$/.test(location.protocol) || !window.fetch) return;
  var form = document.getElementById("upload");
  var list = document.getElementById("upload-result");
  function marked(rank) {  // a shot the person said it cannot take
    var card = document.getElementById("shot-" + rank);
    if (!card) return;
    card.classList.add("skipped");
    var b = card.querySelector(".skip");
    b.disabled = true;
    b.textContent = "Marked: not taken (the next guide asks for another)";
  }
  fetch("api/status").then(function (r) { return r.ok ? r.json() : null; }).then(function (s) {
    if (!s) return;
    form.hidden = false;
    document.getElementById("upload-limit").textContent =
      "Photos go to " + s.inbox + " (JPEG or PNG, at most " + s.max_upload_mb + " MB each).";
    document.querySelectorAll(".skip").forEach(function (b) { b.hidden = false; });
    (s.skipped || []).forEach(marked);
  }).catch(function () {});
  document.querySelectorAll(".skip").forEach(function (b) {
    b.addEventListener("click", function (ev) {
      ev.stopPropagation();
      var rank = Number(b.getAttribute("data-skip"));
      fetch("skip", {method: "POST", body: JSON.stringify({shot: rank}),
                     headers: {"Content-Type": "application/json", "Accept": "application/json"}})
        .then(function (r) { return r.json(); })
        .then(function (res) {
          if (res.error) { list.textContent = ""; say(res.error, false); return; }
          (res.skipped || []).forEach(marked);
        })
        .catch(function (err) { say("Marking failed: " + err, false); });
    });
  });
  function say(text, ok) {
    var li = document.createElement("li");
    li.className = ok ? "ok" : "bad";
    li.textContent = text;
    list.appendChild(li);
  }
  form.addEventListener("submit", function (ev) {
    ev.preventDefault();
    var body = new FormData(form);
    list.textContent = "";
    say("Uploading…", true);
    fetch("upload", {method: "POST", body: body, headers: {"Accept": "application/json"}})
      .then(function (r) { return r.json(); })
      .then(function (res) {
        list.textContent = "";
        (res.accepted || []).forEach(function (a) { say(a.message, true); });
        (res.rejected || []).forEach(function (a) { say(a.message, false); });
        if (res.error) say(res.error, false);
        form.reset();
      })
      .catch(function (err) { list.textContent = ""; say("Upload failed: " + err, false); });
  });
})();
