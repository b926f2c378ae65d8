// scenebot tour viewer: plays the rendered frames, shows the path and viewpoints on a
// top-down overview; clicking a viewpoint jumps there. Data comes from tour_data.js
// (window.TOUR_DATA), so no server is needed (works from file://).
(function () {
  "use strict";
  const data = window.TOUR_DATA;
  if (!data || !data.frames || data.frames.length === 0) {
    throw new Error("tour_data.js is missing or has no frames: re-run the tour stage");
  }
  const NS = "http://www.w3.org/2000/svg";
  const frameImg = document.getElementById("frame");
  const scrub = document.getElementById("scrub");
  const counter = document.getElementById("counter");
  const playBtn = document.getElementById("play");
  const mapImg = document.getElementById("map-image");
  const overlay = document.getElementById("map-overlay");
  const n = data.frames.length;
  let current = 0;
  let timer = null;

  document.getElementById("scene-name").textContent = data.scene || "";
  if (data.video) {
    const a = document.createElement("a");
    a.href = data.video;
    a.textContent = "tour video (" + data.video + ")";
    document.getElementById("links").appendChild(a);
  }
  scrub.max = String(n - 1);

  // overview: image + SVG overlay in the image's pixel coordinates
  mapImg.src = data.overview.src;
  overlay.setAttribute("viewBox", "0 0 " + data.overview.width + " " + data.overview.height);
  const path = document.createElementNS(NS, "polyline");
  path.setAttribute("class", "path");
  path.setAttribute("points", data.path_px.map((p) => p[0] + "," + p[1]).join(" "));
  overlay.appendChild(path);
  const dots = data.viewpoints.map(function (vp, i) {
    const c = document.createElementNS(NS, "circle");
    c.setAttribute("class", "viewpoint");
    c.setAttribute("cx", vp.u);
    c.setAttribute("cy", vp.v);
    c.setAttribute("r", 7);
    c.setAttribute("data-frame", vp.frame);
    c.setAttribute("id", "viewpoint-" + i);
    const title = document.createElementNS(NS, "title");
    title.textContent = "viewpoint " + (i + 1) + " (frame " + vp.frame + ")";
    c.appendChild(title);
    c.addEventListener("click", function () {
      stop();
      show(vp.frame);
    });
    overlay.appendChild(c);
    return c;
  });
  const heading = document.createElementNS(NS, "line");
  heading.setAttribute("class", "heading");
  overlay.appendChild(heading);
  const cam = document.createElementNS(NS, "circle");
  cam.setAttribute("class", "camera");
  cam.setAttribute("r", 5);
  overlay.appendChild(cam);

  function show(i) {
    current = ((i % n) + n) % n;
    frameImg.src = data.frames[current];
    frameImg.setAttribute("data-frame", String(current));
    scrub.value = String(current);
    counter.textContent = "frame " + (current + 1) + " / " + n;
    const p = data.path_px[current];
    const h = data.headings[current];
    cam.setAttribute("cx", p[0]);
    cam.setAttribute("cy", p[1]);
    heading.setAttribute("x1", p[0]);
    heading.setAttribute("y1", p[1]);
    heading.setAttribute("x2", p[0] + 18 * Math.cos(h));
    heading.setAttribute("y2", p[1] - 18 * Math.sin(h)); // image y points down
    dots.forEach(function (d, k) {
      d.classList.toggle("active", data.viewpoints[k].frame === current);
    });
  }
  function play() {
    if (timer === null) {
      timer = window.setInterval(function () { show(current + 1); }, 1000 / data.fps);
      playBtn.textContent = "Pause";
    }
  }
  function stop() {
    if (timer !== null) {
      window.clearInterval(timer);
      timer = null;
    }
    playBtn.textContent = "Play";
  }
  playBtn.addEventListener("click", function () { (timer === null ? play : stop)(); });
  scrub.addEventListener("input", function () { stop(); show(parseInt(scrub.value, 10)); });
  // preload the frames so that playback does not flicker
  data.frames.forEach(function (src) { const im = new Image(); im.src = src; });
  show(0);
  const params = new URLSearchParams(window.location.search);
  if (params.get("autoplay") !== "0") { play(); } else { stop(); }
  window.scenebotTour = { show: show, play: play, stop: stop, current: function () { return current; } };
})();
