// The report page's behaviour (bench/report.py embeds this file): videos that play in sync, a
// frame scrubber cut from side_by_side.mp4, and SVG plots to hover and click. No library, no network.
(function () {
  "use strict";
  const data = JSON.parse(document.getElementById("pibr-data").textContent);
  const SVG = "http://www.w3.org/2000/svg";
  const COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                   "#bcbd22", "#17becf"];

  function el(tag, attrs, parent) {
    const e = document.createElementNS(SVG, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }

  function fmt(v, digits) {
    return v === null || v === undefined ? "—" : Number(v).toFixed(digits);
  }

  // -- videos in sync -------------------------------------------------------------------------------------------
  const videos = Array.from(document.querySelectorAll("video.sync"));
  const run = data.run;
  if (videos.length) {
    const lead = videos[0];
    const tolerance = run ? 1 / run.rate_hz : 0.05;
    const clock = document.getElementById("clock");
    let timer = null;
    const sync = function () {
      const t = lead.currentTime;
      for (const v of videos.slice(1)) {
        if (Math.abs(v.currentTime - t) > tolerance) v.currentTime = t;
      }
      if (clock) clock.textContent = t.toFixed(2) + " s";
    };
    const play = function () {
      sync();
      for (const v of videos) v.play().catch(function () {});
      if (timer === null) timer = setInterval(sync, 200);
    };
    const pause = function () {
      for (const v of videos) v.pause();
      if (timer !== null) { clearInterval(timer); timer = null; }
      sync();
    };
    document.getElementById("play").addEventListener("click", play);
    document.getElementById("pause").addEventListener("click", pause);
    document.getElementById("restart").addEventListener("click", function () {
      for (const v of videos) v.currentTime = 0;
      play();
    });
    lead.addEventListener("ended", pause);
    lead.addEventListener("timeupdate", function () { if (clock) clock.textContent = lead.currentTime.toFixed(2) + " s"; });
  }

  // -- the frame scrubber ---------------------------------------------------------------------------------------
  const cursors = [];   // functions that move each plot's cursor to a tick
  let showTick = function () {};
  const scrub = document.getElementById("scrub-video");
  const slider = document.getElementById("tick");
  if (run && scrub && slider) {
    const canvases = Array.from(document.querySelectorAll("#scrubber canvas"));
    const label = document.getElementById("tick-label");
    let wanted = 0, seeking = false, ready = false;
    const draw = function (tick) {
      const rows = run.methods.length;
      const pw = Math.floor(scrub.videoWidth / 3), ph = Math.floor(scrub.videoHeight / rows);
      for (const c of canvases) {
        const r = Number(c.dataset.row), p = Number(c.dataset.panel);
        c.width = pw; c.height = ph;
        c.getContext("2d").drawImage(scrub, p * pw, r * ph, pw, ph, 0, 0, pw, ph);
        c.dataset.tick = String(tick);
      }
    };
    const seek = function () {
      if (!ready || seeking) return;
      seeking = true;
      const tick = wanted;
      // 'seeked' can fire before the sought frame is presented (Chromium under load drew the old
      // one): draw when the new frame is presented, or after a while if none is (the same frame)
      let drawn = false;
      const finish = function () {
        if (drawn) return;
        drawn = true;
        draw(tick);
        seeking = false;
        if (wanted !== tick) seek();
      };
      scrub.addEventListener("seeked", function done() {
        scrub.removeEventListener("seeked", done);
        if (scrub.requestVideoFrameCallback) {
          scrub.requestVideoFrameCallback(finish);
          setTimeout(finish, 1000);
        } else {
          finish();
        }
      });
      scrub.currentTime = (tick + 0.5) / run.rate_hz;
    };
    const readout = function (tick) {
      for (const cell of document.querySelectorAll("#scrubber .readout")) {
        const s = run.series[cell.dataset.method];
        if (!s) continue;
        const at = function (k) { return s[k] && tick < s[k].length ? s[k][tick] : null; };
        cell.textContent = "DSSIM " + fmt(at("dssim"), 4) + " · PSNR " + fmt(at("psnr"), 2) + " dB · age " +
          fmt(at("age_ms"), 0) + " ms · client " + fmt(at("client_ms"), 1) + " ms · level " + fmt(at("level"), 0);
      }
    };
    showTick = function (tick) {
      tick = Math.max(0, Math.min(Number(slider.max), tick));
      slider.value = String(tick);
      const t = run.series[run.methods[0]].t[tick];
      label.textContent = "tick " + tick + (t === undefined || t === null ? "" : " · " + t.toFixed(3) + " s");
      readout(tick);
      for (const move of cursors) move(tick);
      wanted = tick;
      seek();
    };
    slider.addEventListener("input", function () { showTick(Number(slider.value)); });
    const start = function () { ready = true; showTick(Number(slider.value)); };
    if (scrub.readyState >= 2) start(); else scrub.addEventListener("loadeddata", start, { once: true });
  }

  // -- plots over time ------------------------------------------------------------------------------------------
  // lines: name -> one value (or null) per tick
  function timePlot(parent, key, title, lines) {
    const W = 900, H = 170, L = 60, R = 10, T = 22, B = 24;
    const methods = Object.keys(lines).filter(function (m) { return (lines[m] || []).some(function (v) { return v !== null; }); });
    if (!methods.length) return;
    const n = Math.max.apply(null, methods.map(function (m) { return lines[m].length; }));
    let lo = Infinity, hi = -Infinity;
    for (const m of methods) for (const v of lines[m]) if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    if (hi === lo) { hi += 1; lo -= 1; }
    const x = function (i) { return L + (W - L - R) * (n > 1 ? i / (n - 1) : 0.5); };
    const y = function (v) { return T + (H - T - B) * (1 - (v - lo) / (hi - lo)); };
    const box = document.createElement("div");
    box.className = "plot";
    box.dataset.series = key;
    parent.appendChild(box);
    const svg = el("svg", { viewBox: "0 0 " + W + " " + H, width: W, height: H }, box);
    el("text", { x: L, y: 15, class: "title" }, svg).textContent = title;
    el("text", { x: L - 6, y: T + 4, class: "axis", "text-anchor": "end" }, svg).textContent = fmt(hi, hi < 1 ? 3 : 0);
    el("text", { x: L - 6, y: H - B, class: "axis", "text-anchor": "end" }, svg).textContent = fmt(lo, hi < 1 ? 3 : 0);
    el("text", { x: W - R, y: H - 6, class: "axis", "text-anchor": "end" }, svg).textContent = "tick " + (n - 1);
    el("line", { x1: L, x2: W - R, y1: H - B, y2: H - B, class: "frame" }, svg);
    methods.forEach(function (m, k) {
      const pts = [];
      lines[m].forEach(function (v, i) { if (v !== null) pts.push(x(i).toFixed(1) + "," + y(v).toFixed(1)); });
      el("polyline", { points: pts.join(" "), fill: "none", stroke: COLOURS[k % COLOURS.length], "stroke-width": 1.3, "data-method": m }, svg);
      el("text", { x: L + 8 + 110 * k, y: H - 6, fill: COLOURS[k % COLOURS.length], class: "legend" }, svg).textContent = m;
    });
    const cursor = el("line", { x1: x(0), x2: x(0), y1: T, y2: H - B, class: "cursor" }, svg);
    const hover = el("line", { x1: 0, x2: 0, y1: T, y2: H - B, class: "hover", visibility: "hidden" }, svg);
    const tip = document.createElement("div");
    tip.className = "tip";
    box.appendChild(tip);
    const tickAt = function (ev) {
      const r = svg.getBoundingClientRect();
      const px = (ev.clientX - r.left) * W / r.width;
      return Math.max(0, Math.min(n - 1, Math.round((px - L) / (W - L - R) * (n - 1))));
    };
    svg.addEventListener("mousemove", function (ev) {
      const i = tickAt(ev);
      hover.setAttribute("x1", x(i)); hover.setAttribute("x2", x(i)); hover.setAttribute("visibility", "visible");
      tip.textContent = "tick " + i + ": " + methods.map(function (m) { return m + " " + fmt(lines[m][i], hi < 1 ? 4 : 1); }).join(" · ");
    });
    svg.addEventListener("mouseleave", function () { hover.setAttribute("visibility", "hidden"); tip.textContent = ""; });
    svg.addEventListener("click", function (ev) { showTick(tickAt(ev)); });
    cursors.push(function (i) { cursor.setAttribute("x1", x(i)); cursor.setAttribute("x2", x(i)); });
  }

  if (run) {
    const plots = document.getElementById("plots");
    for (const key in run.series_titles) {
      const lines = {};
      for (const m of run.methods) lines[m] = run.series[m][key] || [];
      timePlot(plots, key, run.series_titles[key], lines);
    }
    for (const key in run.stream_titles) {
      if (run.stream[key]) timePlot(plots, key, run.stream_titles[key], { stream: run.stream[key] });
    }
    if (!scrub) showTick = function (i) { for (const move of cursors) move(i); };
  }

  // -- the pareto scatter ---------------------------------------------------------------------------------------
  const paretoBox = document.getElementById("pareto-plot");
  if (data.pareto && paretoBox) {
    const W = 900, H = 420, L = 60, R = 20, T = 20, B = 40;
    const pts = data.pareto;
    const xs = pts.map(function (p) { return p.ms; }), ys = pts.map(function (p) { return p.dssim; });
    const x0 = 0, x1 = Math.max.apply(null, xs) * 1.05, y0 = 0, y1 = Math.max.apply(null, ys) * 1.05;
    const x = function (v) { return L + (W - L - R) * (v - x0) / (x1 - x0); };
    const y = function (v) { return T + (H - T - B) * (1 - (v - y0) / (y1 - y0)); };
    const svg = el("svg", { viewBox: "0 0 " + W + " " + H, width: W, height: H }, paretoBox);
    el("line", { x1: L, x2: W - R, y1: H - B, y2: H - B, class: "frame" }, svg);
    el("line", { x1: L, x2: L, y1: T, y2: H - B, class: "frame" }, svg);
    el("text", { x: W - R, y: H - 8, class: "axis", "text-anchor": "end" }, svg).textContent = "client ms (" + pts[0].size + "), max " + fmt(x1, 0);
    el("text", { x: L + 4, y: T + 10, class: "axis" }, svg).textContent = "DSSIM, max " + fmt(y1, 3);
    const label = document.createElement("div");
    label.className = "tip";
    label.id = "pareto-label";
    paretoBox.appendChild(label);
    const scenes = Array.from(new Set(pts.map(function (p) { return p.scene; })));
    for (const p of pts) {
      const c = el("circle", { cx: x(p.ms), cy: y(p.dssim), r: 5, fill: COLOURS[scenes.indexOf(p.scene) % COLOURS.length],
                               "data-variant": p.variant }, svg);
      el("title", {}, c).textContent = p.variant;
      c.addEventListener("mouseenter", function () {
        label.textContent = p.scene + " · " + p.variant + ": DSSIM " + fmt(p.dssim, 4) + ", " + fmt(p.ms, 1) + " ms";
      });
    }
  }
}());
