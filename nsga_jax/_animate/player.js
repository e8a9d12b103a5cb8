// The player of an nsga_jax animation page: draws the frames that the page
// carries (the JSON of #animation-data, written by nsga_jax/_animate/html.py)
// on a canvas, with play/pause, a frame slider and, in 3D, drag to turn the
// view. It mirrors nsga_jax/_animate/screen.py: the same view, fit, drawing
// order and colours, so that the page and the GIF show the same frames.
(function () {
  "use strict";
  const data = JSON.parse(document.getElementById("animation-data").textContent);
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const slider = document.getElementById("frame");
  const button = document.getElementById("play");
  const clock = document.getElementById("time");
  const controls = document.getElementById("controls");
  const frames = data.times.length;
  const moving = data.moving;
  const fixed = data.fixed;
  const movingCount = moving.length ? moving[0].length / 3 : 0;
  const items = data.items.map(function (item) {
    let points = item.points;
    if (!points) {
      points = [];
      for (let k = 0; k < item.range[1]; k++) points.push(item.range[0] + k);
    }
    return { kind: item.kind, shape: item.shape, points: points, radius: item.radius || 0 };
  });
  const view = { azimuth: data.view.azimuth, elevation: data.view.elevation };
  let frame = 0;
  let playing = true;
  let hold = 0;

  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function cross(a, b) {
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  }
  function scale(a, s) { return [a[0] * s, a[1] * s, a[2] * s]; }
  function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
  function unit(a) { return scale(a, 1 / Math.sqrt(dot(a, a))); }

  function camera() {
    const up = unit(data.up);
    const helper = Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    const h1 = unit(add(helper, scale(up, -dot(helper, up))));
    const h2 = cross(up, h1);
    const ce = Math.cos(view.elevation), se = Math.sin(view.elevation);
    const toward = add(scale(add(scale(h1, Math.cos(view.azimuth)), scale(h2, Math.sin(view.azimuth))), ce),
      scale(up, se));
    const right = unit(cross(up, toward));
    return { right: right, up: cross(toward, right), toward: toward };
  }

  function project(p, cam) {  // picture x, y [m] and depth (larger: nearer)
    if (data.dim === 2) return [p[0], p[1], 0];
    return [dot(p, cam.right), dot(p, cam.up), dot(p, cam.toward)];
  }

  function fit(cam, width, height) {
    const low = data.focus[0], high = data.focus[1];
    let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
    for (const x of [low[0], high[0]]) for (const y of [low[1], high[1]]) for (const z of [low[2], high[2]]) {
      const p = project([x, y, z], cam);
      lo = [Math.min(lo[0], p[0]), Math.min(lo[1], p[1])];
      hi = [Math.max(hi[0], p[0]), Math.max(hi[1], p[1])];
    }
    const size = Math.max(high[0] - low[0], high[1] - low[1], high[2] - low[2]) || 1;
    const floor = 1e-3 * size;
    const available = [width - 2 * data.margin, height - data.titleBand - 2 * data.margin];
    const s = Math.min(available[0] / Math.max(hi[0] - lo[0], floor), available[1] / Math.max(hi[1] - lo[1], floor));
    return {
      scale: s, centre: [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2],
      centrePx: [width / 2, data.titleBand + data.margin + available[1] / 2],
    };
  }

  function point(f, i) {
    if (i < movingCount) return [moving[f][3 * i], moving[f][3 * i + 1], moving[f][3 * i + 2]];
    const k = 3 * (i - movingCount);
    return [fixed[k], fixed[k + 1], fixed[k + 2]];
  }

  function shade(colour, factor) {
    let out = "#";
    for (const i of [1, 3, 5]) {
      const c = Math.min(255, Math.max(0, Math.round(parseInt(colour.substr(i, 2), 16) * factor)));
      out += (c < 16 ? "0" : "") + c.toString(16);
    }
    return out;
  }

  function faceLight(pts, cam) {  // Newell's normal against a light above and behind the viewer
    const n = [0, 0, 0];
    for (let k = 0; k < pts.length; k++) {
      const a = pts[k], b = pts[(k + 1) % pts.length];
      n[0] += (a[1] - b[1]) * (a[2] + b[2]);
      n[1] += (a[2] - b[2]) * (a[0] + b[0]);
      n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    const length = Math.sqrt(dot(n, n));
    if (length === 0) return 1;
    const light = add(add(cam.toward, scale(cam.up, 0.6)), scale(cam.right, 0.3));
    return 0.55 + 0.45 * Math.abs(dot(n, light)) / (length * Math.sqrt(dot(light, light)));
  }

  function isActive(f, index) {
    const flags = data.active[index];
    return flags === undefined || flags.charAt(f) === "1";
  }

  function path(pts, close) {
    ctx.beginPath();
    ctx.moveTo(pts[0][0], pts[0][1]);
    for (let k = 1; k < pts.length; k++) ctx.lineTo(pts[k][0], pts[k][1]);
    if (close) ctx.closePath();
  }

  function stroke(colour, width) {
    if (!colour) return;
    ctx.strokeStyle = colour;
    ctx.lineWidth = width;
    ctx.stroke();
  }

  function arrow(style, a, b) {
    const d = [b[0] - a[0], b[1] - a[1]];
    const length = Math.hypot(d[0], d[1]);
    if (length < 1) return;
    const u = [d[0] / length, d[1] / length], n = [-u[1], u[0]];
    const tip = Math.min(10, 0.5 * length);
    const base = [b[0] - tip * u[0], b[1] - tip * u[1]];
    path([a, base], false);
    stroke(style.stroke, style.width);
    path([b, [base[0] + 0.45 * tip * n[0], base[1] + 0.45 * tip * n[1]],
      [base[0] - 0.45 * tip * n[0], base[1] - 0.45 * tip * n[1]]], true);
    ctx.fillStyle = style.fill;
    ctx.fill();
    stroke(style.stroke, 1);
  }

  function spring(a, b) {
    const d = [b[0] - a[0], b[1] - a[1]];
    const length = Math.hypot(d[0], d[1]);
    if (length < 1e-9) return [a, b];
    const u = [d[0] / length, d[1] / length], n = [-u[1], u[0]];
    const steps = 2 * data.springCoils, pts = [a];
    for (let k = 0; k <= steps; k++) {
      const s = (0.15 + 0.7 * k / steps) * length;
      const side = (k === 0 || k === steps) ? 0 : (k % 2 === 1 ? 5 : -5);
      pts.push([a[0] + s * u[0] + side * n[0], a[1] + s * u[1] + side * n[1]]);
    }
    pts.push(b);
    return pts;
  }

  function draw() {
    const width = canvas.clientWidth, height = canvas.clientHeight;
    const ratio = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.fillStyle = "#ffffff";
    ctx.fillRect(0, 0, width, height);
    const cam = camera();
    const fitted = fit(cam, width, height);
    const list = [];
    items.forEach(function (item, index) {
      if (!isActive(frame, index)) return;
      const style = data.styles[item.kind];
      const world = item.points.map(function (i) { return point(frame, i); });
      let near = 0;
      const px = world.map(function (p) {
        const q = project(p, cam);
        near += q[2];
        return [fitted.centrePx[0] + fitted.scale * (q[0] - fitted.centre[0]),
          fitted.centrePx[1] - fitted.scale * (q[1] - fitted.centre[1])];
      });
      near = (data.dim === 3 && style.by_depth) ? near / world.length : 0;
      list.push({ item: item, index: index, style: style, world: world, px: px, near: near });
    });
    list.sort(function (a, b) { return a.style.layer - b.style.layer || a.near - b.near || a.index - b.index; });
    ctx.lineJoin = "round";
    ctx.lineCap = "round";
    for (const entry of list) {
      const item = entry.item, style = entry.style, px = entry.px;
      if (item.shape === "polygon") {
        let fill = style.fill;
        if (data.dim === 3 && (item.kind === "body" || item.kind === "solid")) {
          fill = shade(fill, faceLight(entry.world, cam));
        }
        path(px, true);
        if (fill) { ctx.fillStyle = fill; ctx.fill(); }
        stroke(style.stroke, style.width);
      } else if (item.shape === "dot") {
        const r = item.radius > 0 ? item.radius * fitted.scale : style.marker;
        for (const p of px) {
          ctx.beginPath();
          ctx.arc(p[0], p[1], r, 0, 2 * Math.PI);
          if (style.fill) { ctx.fillStyle = style.fill; ctx.fill(); }
          stroke(style.stroke, style.width);
        }
      } else if (item.shape === "arrow") {
        arrow(style, px[0], px[1]);
      } else if (item.shape === "spring") {
        path(spring(px[0], px[1]), false);
        stroke(style.stroke, style.width);
      } else if (item.shape === "segments") {
        ctx.beginPath();
        for (let k = 0; k + 1 < px.length; k += 2) {
          ctx.moveTo(px[k][0], px[k][1]);
          ctx.lineTo(px[k + 1][0], px[k + 1][1]);
        }
        stroke(style.stroke, style.width);
      } else {
        path(px, false);
        stroke(style.stroke, style.width);
      }
    }
    ctx.fillStyle = "#202020";
    ctx.textBaseline = "middle";
    ctx.font = "15px sans-serif";
    ctx.textAlign = "left";
    ctx.fillText(data.title, 10, 18);
    ctx.font = "15px monospace";
    ctx.textAlign = "right";
    ctx.fillText(data.labels[frame], width - 10, 18);
    slider.value = String(frame);
    clock.textContent = data.labels[frame] + "  (" + (frame + 1) + "/" + frames + ")";
  }

  function layout() {
    canvas.style.width = window.innerWidth + "px";
    canvas.style.height = Math.max(100, window.innerHeight - controls.offsetHeight) + "px";
    draw();
  }

  function setPlaying(on) {
    playing = on && frames > 1;
    button.textContent = playing ? "Pause" : "Play";
  }

  function tick() {
    if (!playing) return;
    if (frame === frames - 1) {
      hold += 1;
      if (hold * 1000 / data.fps < data.holdLast * 1000) return;
      hold = 0;
      frame = 0;
    } else {
      frame += 1;
    }
    draw();
  }

  slider.max = String(frames - 1);
  slider.addEventListener("input", function () { setPlaying(false); frame = Number(slider.value); draw(); });
  button.addEventListener("click", function () { setPlaying(!playing); });
  window.addEventListener("keydown", function (event) {
    if (event.key === " ") { setPlaying(!playing); event.preventDefault(); }
    if (event.key === "ArrowRight" || event.key === "ArrowLeft") {
      setPlaying(false);
      frame = Math.min(frames - 1, Math.max(0, frame + (event.key === "ArrowRight" ? 1 : -1)));
      draw();
    }
  });
  if (data.dim === 3) {
    let last = null;
    canvas.style.cursor = "grab";
    canvas.addEventListener("pointerdown", function (event) {
      last = [event.clientX, event.clientY];
      canvas.setPointerCapture(event.pointerId);
    });
    canvas.addEventListener("pointermove", function (event) {
      if (!last) return;
      view.azimuth -= 0.01 * (event.clientX - last[0]);
      view.elevation = Math.max(-1.55, Math.min(1.55, view.elevation + 0.01 * (event.clientY - last[1])));
      last = [event.clientX, event.clientY];
      draw();
    });
    canvas.addEventListener("pointerup", function () { last = null; });
    canvas.addEventListener("dblclick", function () {
      view.azimuth = data.view.azimuth;
      view.elevation = data.view.elevation;
      draw();
    });
  }
  window.addEventListener("resize", layout);
  const turned = /view=(-?[\d.]+),(-?[\d.]+)/.exec(window.location.hash);  // azimuth, elevation [deg]
  if (turned && data.dim === 3) {
    view.azimuth = Number(turned[1]) * Math.PI / 180;
    view.elevation = Math.max(-1.55, Math.min(1.55, Number(turned[2]) * Math.PI / 180));
  }
  const start = /frame=(\d+)/.exec(window.location.hash);
  if (start) {
    frame = Math.min(frames - 1, Number(start[1]));
    setPlaying(false);
  } else {
    setPlaying(true);
  }
  layout();
  setInterval(tick, 1000 / data.fps);
})();
