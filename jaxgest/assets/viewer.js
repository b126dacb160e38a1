// jaxgest viewer: a hand-written canvas-2D renderer of skeleton clips (no library, no network).
// Reads the JSON in #jaxgest-data (written by jaxgest/viewer.py), draws one panel per clip (or all clips
// in one panel), plays them back synchronised by time, and shares one orbit camera between the panels.
// With speech (data.audio) the <audio> element's clock leads the playback while it plays.
"use strict";
(function () {
  var root = document.documentElement;
  var errors = [];
  var resources = [];
  var statusEl = document.getElementById("jaxgest-status");

  function showErrors() {
    var box = document.getElementById("errors");
    root.setAttribute("data-errors", String(errors.length));
    if (box && errors.length) { box.hidden = false; box.textContent = errors.join("\n"); }
    writeStatus();
  }
  window.addEventListener("error", function (e) {
    errors.push("error: " + (e.message || "resource failed to load") + (e.filename ? " (" + e.filename + ":" + e.lineno + ")" : ""));
    showErrors();
  }, true);
  window.addEventListener("unhandledrejection", function (e) {
    errors.push("unhandled rejection: " + String(e.reason));
    showErrors();
  });
  document.addEventListener("securitypolicyviolation", function (e) {
    errors.push("blocked by the page's policy: " + e.blockedURI);
    showErrors();
  });
  if (window.PerformanceObserver) {  // any fetched resource (there should be none) is listed in the status
    try {
      new PerformanceObserver(function (list) {
        list.getEntries().forEach(function (en) { resources.push(en.name); });
        writeStatus();
      }).observe({ type: "resource", buffered: true });
    } catch (err) { /* old browsers: no resource timing */ }
  }

  // ---------------------------------------------------------------- data
  var data = JSON.parse(document.getElementById("jaxgest-data").textContent);
  var colors = data.colors;
  var PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
                 "#7f7f7f", "#bcbd22"];

  function b64bytes(s) {
    var bin = atob(s), out = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }
  // the same arithmetic as jaxgest.viewer.decode_clip: centroid (float32) + lo + q * step
  function decode(c) {
    var F = c.frames, J = c.joints.length;
    var cb = b64bytes(c.center), qb = b64bytes(c.q);
    var cv = new DataView(cb.buffer), qv = new DataView(qb.buffer);
    var pos = new Float64Array(F * J * 3);
    for (var f = 0; f < F; f++) {
      for (var a = 0; a < 3; a++) {
        var ctr = cv.getFloat32((f * 3 + a) * 4, true) + c.lo[a];
        for (var j = 0; j < J; j++) {
          var k = (f * J + j) * 3 + a;
          pos[k] = ctr + qv.getUint16(k * 2, true) * c.step[a];
        }
      }
    }
    return pos;
  }

  var clips = data.clips.map(function (c, k) {
    var pos = decode(c), J = c.joints.length;
    var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (var i = 0; i < pos.length; i++) {
      var a = i % 3;
      if (pos[i] < lo[a]) lo[a] = pos[i];
      if (pos[i] > hi[a]) hi[a] = pos[i];
    }
    var footMin = Infinity;
    c.feet.forEach(function (j) {
      for (var f = 0; f < c.frames; f++) footMin = Math.min(footMin, pos[(f * J + j) * 3 + 1]);
    });
    var bones = [];
    c.parents.forEach(function (p, j) { if (p >= 0) bones.push([p, j]); });
    return { meta: c, pos: pos, J: J, lo: lo, hi: hi, bones: bones, footMin: footMin, index: k,
             tint: PALETTE[k % PALETTE.length] };
  });
  var fpsRef = Math.max.apply(null, clips.map(function (c) { return c.meta.fps; }));
  var duration = Math.max.apply(null, clips.map(function (c) { return c.meta.duration; }));
  var lastTime = Math.max(0, Math.round(duration * fpsRef) - 1) / fpsRef;  // time of the last shown frame

  function frameOf(clip, t) {
    return Math.max(0, Math.min(clip.meta.frames - 1, Math.round(t * clip.meta.fps + 1e-9)));
  }
  function P(clip, f, j) {
    var k = (f * clip.J + j) * 3;
    return [clip.pos[k], clip.pos[k + 1], clip.pos[k + 2]];
  }

  // ---------------------------------------------------------------- state
  var bbLo = [Infinity, Infinity, Infinity], bbHi = [-Infinity, -Infinity, -Infinity];
  clips.forEach(function (c) {
    for (var a = 0; a < 3; a++) { bbLo[a] = Math.min(bbLo[a], c.lo[a]); bbHi[a] = Math.max(bbHi[a], c.hi[a]); }
  });
  bbLo[1] = Math.min(bbLo[1], 0);
  var FOV = 35 * Math.PI / 180;
  var radius = 0.5 * Math.max(bbHi[0] - bbLo[0], bbHi[1] - bbLo[1], bbHi[2] - bbLo[2], 0.5);
  var SLENDER = Math.max(1, Math.min(2.2, (bbHi[1] - bbLo[1]) / Math.max(bbHi[0] - bbLo[0], bbHi[2] - bbLo[2], 0.1)));
  var HOME = { yaw: 25 * Math.PI / 180, pitch: 10 * Math.PI / 180, dist: 1.2 * radius / Math.tan(FOV / 2),
               target: [(bbLo[0] + bbHi[0]) / 2, (bbLo[1] + bbHi[1]) / 2, (bbLo[2] + bbHi[2]) / 2] };
  var cam = { yaw: HOME.yaw, pitch: HOME.pitch, dist: HOME.dist, target: HOME.target.slice() };
  var gridStep = 0.5;
  var gridC = [Math.round(HOME.target[0] / gridStep) * gridStep, Math.round(HOME.target[2] / gridStep) * gridStep];
  var gridR = Math.max(2, Math.ceil((radius * 1.6) / gridStep) * gridStep);

  var state = { t: 0, playing: true, speed: 1, loop: true, overlay: !!data.options.overlay,
                trails: !!data.options.trails, trailSeconds: data.options.trailSeconds || 1, sound: true,
                clock: "wall", audioTime: null };

  // URL hash: #t=1.5&paused=1&view=front|side&overlay=1&trails=1&trail=2&speed=0.5&yaw=..&pitch=..(deg)
  var hash = {};
  location.hash.replace(/^#/, "").split("&").forEach(function (kv) {
    if (!kv) return;
    var i = kv.indexOf("=");
    hash[decodeURIComponent(i < 0 ? kv : kv.slice(0, i))] = i < 0 ? "1" : decodeURIComponent(kv.slice(i + 1));
  });
  function num(v, d) { var x = parseFloat(v); return isFinite(x) ? x : d; }
  if (hash.t !== undefined) state.t = Math.max(0, Math.min(lastTime, num(hash.t, 0)));
  if (hash.frame !== undefined) state.t = Math.max(0, Math.min(lastTime, num(hash.frame, 0) / fpsRef));
  if (hash.paused === "1" || hash.t !== undefined || hash.frame !== undefined) state.playing = hash.play === "1";
  if (hash.overlay !== undefined) state.overlay = hash.overlay === "1";
  if (hash.trails !== undefined) state.trails = hash.trails === "1";
  if (hash.trail !== undefined) state.trailSeconds = Math.max(0.1, num(hash.trail, 1));
  if (hash.speed !== undefined) state.speed = Math.max(0.25, Math.min(2, num(hash.speed, 1)));
  if (hash.loop !== undefined) state.loop = hash.loop === "1";
  if (hash.sound !== undefined) state.sound = hash.sound !== "0";
  if (hash.view === "front") { cam.yaw = 0; cam.pitch = 0; }
  if (hash.view === "side") { cam.yaw = Math.PI / 2; cam.pitch = 0; }
  if (hash.yaw !== undefined) cam.yaw = num(hash.yaw, 25) * Math.PI / 180;
  if (hash.pitch !== undefined) cam.pitch = num(hash.pitch, 10) * Math.PI / 180;

  // ---------------------------------------------------------------- camera
  function basis() {
    var cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch), cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw);
    var eye = [cam.target[0] + cam.dist * sy * cp, cam.target[1] + cam.dist * sp, cam.target[2] + cam.dist * cy * cp];
    var fwd = [-sy * cp, -sp, -cy * cp];
    var right = [cy, 0, -sy];  // fwd x up, normalised: the character's left (+X) is image right at yaw 0
    var up = [right[1] * fwd[2] - right[2] * fwd[1], right[2] * fwd[0] - right[0] * fwd[2], right[0] * fwd[1] - right[1] * fwd[0]];
    return { eye: eye, fwd: fwd, right: right, up: up };
  }
  var NEAR = 0.05;
  function View(canvas) {
    var b = basis(), w = canvas.width, h = canvas.height;
    // fit the clips' height in a tall, narrow panel too: a standing body is about twice as tall as it is wide
    var focal = 0.5 * Math.min(h, w * SLENDER) / Math.tan(FOV / 2);
    var toCam = function (p) {
      var v = [p[0] - b.eye[0], p[1] - b.eye[1], p[2] - b.eye[2]];
      return [v[0] * b.right[0] + v[1] * b.right[1] + v[2] * b.right[2],
              v[0] * b.up[0] + v[1] * b.up[1] + v[2] * b.up[2],
              v[0] * b.fwd[0] + v[1] * b.fwd[1] + v[2] * b.fwd[2]];
    };
    var toScreen = function (c) { return [w / 2 + focal * c[0] / c[2], h / 2 - focal * c[1] / c[2]]; };
    return {
      focal: focal, basis: b, toCam: toCam, toScreen: toScreen,
      // a 3D segment as screen points, clipped at the near plane (null when wholly behind it)
      seg: function (p, q) {
        var a = toCam(p), c = toCam(q);
        if (a[2] < NEAR && c[2] < NEAR) return null;
        if (a[2] < NEAR || c[2] < NEAR) {
          var s = (NEAR - a[2]) / (c[2] - a[2]);
          var m = [a[0] + s * (c[0] - a[0]), a[1] + s * (c[1] - a[1]), NEAR];
          if (a[2] < NEAR) a = m; else c = m;
        }
        return [toScreen(a), toScreen(c), (a[2] + c[2]) / 2];
      }
    };
  }

  // ---------------------------------------------------------------- panels
  var panelsEl = document.getElementById("panels");
  var panels = [];
  function mix(hex, amount) {  // towards white
    var n = parseInt(hex.slice(1), 16), r = n >> 16, g = (n >> 8) & 255, b = n & 255;
    var f = function (x) { return Math.round(x + (255 - x) * amount); };
    return "rgb(" + f(r) + "," + f(g) + "," + f(b) + ")";
  }
  function buildPanels() {
    panelsEl.innerHTML = "";
    panels = [];
    var groups = state.overlay ? [clips] : clips.map(function (c) { return [c]; });
    panelsEl.style.gridTemplateColumns = "repeat(" + groups.length + ", minmax(140px, 1fr))";
    groups.forEach(function (group, k) {
      var div = document.createElement("div");
      div.className = "panel";
      div.setAttribute("data-panel", String(k));
      var h = document.createElement("h2");
      if (state.overlay) {
        h.textContent = "overlay";
        var legend = document.createElement("div");
        legend.className = "legend";
        group.forEach(function (c) {
          var s = document.createElement("span"), i = document.createElement("i");
          i.style.background = c.tint;
          s.appendChild(i);
          s.appendChild(document.createTextNode(c.meta.title));
          legend.appendChild(s);
        });
        div.appendChild(h);
        div.appendChild(legend);
      } else {
        h.textContent = group[0].meta.title;
        h.title = group[0].meta.title;
        div.appendChild(h);
      }
      var canvas = document.createElement("canvas");
      div.appendChild(canvas);
      var cap = document.createElement("div");
      cap.className = "caption mono";
      div.appendChild(cap);
      panelsEl.appendChild(div);
      attachMouse(canvas);
      panels.push({ div: div, canvas: canvas, caption: cap, clips: group });
    });
    resize();
  }
  function resize() {
    var dpr = window.devicePixelRatio || 1;
    panels.forEach(function (p) {
      var r = p.canvas.getBoundingClientRect();
      var w = Math.max(1, Math.round(r.width * dpr)), h = Math.max(1, Math.round(r.height * dpr));
      if (p.canvas.width !== w || p.canvas.height !== h) { p.canvas.width = w; p.canvas.height = h; }
    });
    dirty = true;
  }

  // ---------------------------------------------------------------- drawing
  function line(ctx, s, color, width) {
    ctx.strokeStyle = color;
    ctx.lineWidth = width;
    ctx.beginPath();
    ctx.moveTo(s[0][0], s[0][1]);
    ctx.lineTo(s[1][0], s[1][1]);
    ctx.stroke();
  }
  function drawGrid(ctx, view, scale) {
    var n = Math.round(gridR / gridStep);
    for (var i = -n; i <= n; i++) {
      var x = gridC[0] + i * gridStep, z = gridC[1] + i * gridStep;
      var col = i === 0 ? "#c4c4c4" : "#e2e2e2";
      var a = view.seg([x, 0, gridC[1] - gridR], [x, 0, gridC[1] + gridR]);
      if (a) line(ctx, a, col, scale);
      var b = view.seg([gridC[0] - gridR, 0, z], [gridC[0] + gridR, 0, z]);
      if (b) line(ctx, b, col, scale);
    }
  }
  function boneColor(clip, j, tinted) {
    var side = clip.meta.side.charAt(j);
    if (!tinted) return colors[side] || colors.C;
    return side === "R" ? mix(clip.tint, 0.45) : clip.tint;
  }
  function drawShadowsAndContacts(ctx, view, clip, f, scale) {
    ctx.lineCap = "round";
    clip.bones.forEach(function (bj) {
      var p = P(clip, f, bj[0]), q = P(clip, f, bj[1]);
      var s = view.seg([p[0], 0, p[2]], [q[0], 0, q[2]]);
      if (s) line(ctx, s, "rgba(0,0,0,0.13)", Math.max(2, 0.03 * view.focal / Math.max(s[2], NEAR)));
    });
    // contact marks: a foot joint within 3 cm of the clip's lowest foot height touches the floor
    clip.meta.feet.forEach(function (j) {
      var p = P(clip, f, j);
      if (p[1] > clip.footMin + 0.03) return;
      var c = view.toCam([p[0], 0.001, p[2]]);
      if (c[2] < NEAR) return;
      var s = view.toScreen(c), r = 0.06 * view.focal / c[2];
      ctx.fillStyle = "rgba(30,140,60,0.35)";
      ctx.beginPath();
      ctx.ellipse(s[0], s[1], r, Math.max(1, r * Math.abs(Math.sin(cam.pitch)) + scale), 0, 0, 2 * Math.PI);
      ctx.fill();
    });
  }
  function drawTrails(ctx, view, clip, t, tinted, scale) {
    var f1 = frameOf(clip, t), f0 = Math.max(0, frameOf(clip, t - state.trailSeconds));
    if (f1 - f0 < 1) return;
    clip.meta.hands.forEach(function (j) {
      var col = boneColor(clip, j, tinted);
      for (var f = f0; f < f1; f++) {
        var s = view.seg(P(clip, f, j), P(clip, f + 1, j));
        if (!s) continue;
        ctx.globalAlpha = 0.3 + 0.7 * (f - f0 + 1) / (f1 - f0);
        line(ctx, s, col, 2 * scale);
      }
      ctx.globalAlpha = 1;
    });
  }
  function drawSkeleton(ctx, view, clip, f, tinted, scale) {
    var segs = [];
    clip.bones.forEach(function (bj) {
      var s = view.seg(P(clip, f, bj[0]), P(clip, f, bj[1]));
      if (s) segs.push([s, bj[1]]);
    });
    segs.sort(function (a, b) { return b[0][2] - a[0][2]; });  // far first (painter's order)
    ctx.lineCap = "round";
    segs.forEach(function (e) {
      var s = e[0];
      line(ctx, s, boneColor(clip, e[1], tinted), Math.max(1.5 * scale, 0.03 * view.focal / s[2]));
    });
    ctx.fillStyle = "#222";
    for (var j = 0; j < clip.J; j++) {
      var c = view.toCam(P(clip, f, j));
      if (c[2] < NEAR) continue;
      var p = view.toScreen(c), r = Math.max(1.2 * scale, 0.012 * view.focal / c[2]);
      ctx.beginPath();
      ctx.arc(p[0], p[1], r, 0, 2 * Math.PI);
      ctx.fill();
    }
    var hj = clip.meta.head;
    if (hj >= 0) {
      var hc = view.toCam(P(clip, f, hj));
      if (hc[2] >= NEAR) {
        var hp = view.toScreen(hc), hr = 0.09 * view.focal / hc[2];
        ctx.fillStyle = "#fff";
        ctx.strokeStyle = tinted ? clip.tint : "#333";
        ctx.lineWidth = Math.max(1.5 * scale, 0.012 * view.focal / hc[2]);
        ctx.beginPath();
        ctx.arc(hp[0], hp[1], hr, 0, 2 * Math.PI);
        ctx.fill();
        ctx.stroke();
      }
    }
  }
  function draw() {
    var scale = window.devicePixelRatio || 1;
    panels.forEach(function (p) {
      var ctx = p.canvas.getContext("2d"), view = View(p.canvas);
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.fillStyle = "#fbfbfb";
      ctx.fillRect(0, 0, p.canvas.width, p.canvas.height);
      drawGrid(ctx, view, scale);
      var tinted = state.overlay;
      p.clips.forEach(function (c) { drawShadowsAndContacts(ctx, view, c, frameOf(c, state.t), scale); });
      if (state.trails) p.clips.forEach(function (c) { drawTrails(ctx, view, c, state.t, tinted, scale); });
      p.clips.forEach(function (c) { drawSkeleton(ctx, view, c, frameOf(c, state.t), tinted, scale); });
      p.caption.textContent = p.clips.map(function (c) {
        return (p.clips.length > 1 ? c.meta.title + ": " : "") + "frame " + frameOf(c, state.t) + " / " +
          c.meta.frames + " @ " + c.meta.fps + " fps";
      }).join("  ");
    });
    updateControls();
    if (root.getAttribute("data-ready") !== "1") root.setAttribute("data-ready", "1");
    writeStatus();
  }

  // ---------------------------------------------------------------- speech
  // The embedded speech covers the page's time line exactly (jaxgest.viewer.encode_audio applied the
  // offset), so while it plays the page's time IS audio.currentTime: the audio clock leads and the drawn frame
  // follows it. Paused, scrubbed or stepped, the page moves the audio to its own time. Where the browser will
  // not start sound before the user has touched the page (autoplay policy), the motion plays on the wall clock
  // and the speech joins, in step, at the first click or key press.
  var audio = null, soundBlocked = false;
  if (data.audio) {
    audio = document.createElement("audio");
    audio.id = "jaxgest-audio";
    audio.preload = "auto";
    audio.hidden = true;
    audio.addEventListener("error", function () {
      errors.push("speech: the browser cannot play the embedded " + data.audio.codec + " audio (media error " +
                  (audio.error ? audio.error.code : "?") + ")");
      showErrors();
    });
    audio.src = data.audio.src;
    document.body.appendChild(audio);
  }
  function audioSeek(t) {
    if (audio && Math.abs(audio.currentTime - t) > 1e-4) audio.currentTime = t;
  }
  function soundHint() {
    var h = document.getElementById("soundHint");
    if (h) h.hidden = !(audio && soundBlocked && state.playing && state.sound);
  }
  // make the audio follow the page: playing or not, speed, sound on or off
  function audioSync() {
    if (!audio) return;
    audio.playbackRate = state.speed;
    audio.muted = !state.sound;
    if (state.playing && audio.paused && state.t < lastTime) {
      audioSeek(state.t);
      var started = audio.play();
      if (started && started.then) {
        started.then(function () { soundBlocked = false; soundHint(); }, function (e) {
          if (e && e.name === "NotAllowedError") soundBlocked = true;  // autoplay policy: wall clock until a gesture
          else if (!e || e.name !== "AbortError") { errors.push("speech: " + String(e)); showErrors(); }
          soundHint();
        });
      }
    } else if (!state.playing && !audio.paused) {
      audio.pause();
      audioSeek(state.t);
    }
    soundHint();
  }
  function userGesture() { if (audio && soundBlocked) { soundBlocked = false; audioSync(); } }
  document.addEventListener("pointerdown", userGesture, true);
  document.addEventListener("keydown", userGesture, true);

  // ---------------------------------------------------------------- controls
  var el = function (id) { return document.getElementById(id); };
  var scrub = el("scrub"), clock = el("clock"), playBtn = el("play");
  scrub.max = String(lastTime);
  scrub.step = String(1 / fpsRef);
  var nRef = Math.round(lastTime * fpsRef) + 1;
  function updateControls() {
    scrub.value = String(state.t);
    playBtn.innerHTML = state.playing ? "&#10074;&#10074;" : "&#9654;";
    clock.textContent = "frame " + Math.round(state.t * fpsRef) + " / " + nRef + " \u00b7 " +
      state.t.toFixed(3) + " / " + duration.toFixed(3) + " s";
    root.setAttribute("data-time", state.t.toFixed(6));
    soundHint();
  }
  function writeStatus() {
    if (!statusEl || !clips || !state) return;  // an error before the page is set up: data-errors tells
    statusEl.textContent = JSON.stringify(info());
  }
  function info() {
    return {
      version: data.version, ready: root.getAttribute("data-ready") === "1", time: state.t,
      playing: state.playing, overlay: state.overlay, panels: panels.length, duration: duration,
      fpsRef: fpsRef, errors: errors.slice(), resources: resources.slice(), clock: state.clock,
      audio: audio ? { codec: data.audio.codec, offset: data.audio.offset, embeddedDuration: data.audio.duration,
                       duration: audio.duration, readyState: audio.readyState, currentTime: audio.currentTime,
                       paused: audio.paused, muted: audio.muted, playbackRate: audio.playbackRate,
                       blocked: soundBlocked, drawnAt: state.audioTime } : null,
      clips: clips.map(function (c) {
        return { title: c.meta.title, frames: c.meta.frames, fps: c.meta.fps, duration: c.meta.duration,
                 joints: c.J, frame: frameOf(c, state.t) };
      })
    };
  }
  var dirty = true;
  function setTime(t) {
    state.t = Math.max(0, Math.min(lastTime, t)); state.clock = "wall"; state.audioTime = null;
    audioSeek(state.t); dirty = true;
  }
  function setPlaying(on) { state.playing = on; audioSync(); dirty = true; }
  function step(n) { setPlaying(false); setTime(Math.round(state.t * fpsRef + n) / fpsRef); }

  playBtn.addEventListener("click", function () {
    if (!state.playing && state.t >= lastTime) setTime(0);
    setPlaying(!state.playing);
  });
  scrub.addEventListener("input", function () { setPlaying(false); setTime(parseFloat(scrub.value)); });
  el("speed").value = String(state.speed);
  el("speed").addEventListener("change", function () { state.speed = parseFloat(el("speed").value); audioSync(); });
  if (audio) el("soundLabel").hidden = false;
  el("sound").checked = state.sound;
  el("sound").addEventListener("change", function () { state.sound = el("sound").checked; audioSync(); });
  el("loop").checked = state.loop;
  el("loop").addEventListener("change", function () { state.loop = el("loop").checked; });
  el("overlay").checked = state.overlay;
  el("overlay").addEventListener("change", function () { state.overlay = el("overlay").checked; buildPanels(); });
  el("trails").checked = state.trails;
  el("trails").addEventListener("change", function () { state.trails = el("trails").checked; dirty = true; });
  el("trailSeconds").value = String(state.trailSeconds);
  el("trailSeconds").addEventListener("change", function () {
    state.trailSeconds = Math.max(0.1, num(el("trailSeconds").value, 1)); dirty = true;
  });
  function setCam(yaw, pitch, reset) {
    if (reset) { cam.dist = HOME.dist; cam.target = HOME.target.slice(); }
    cam.yaw = yaw; cam.pitch = pitch; dirty = true;
  }
  el("camReset").addEventListener("click", function () { setCam(HOME.yaw, HOME.pitch, true); });
  el("camFront").addEventListener("click", function () { setCam(0, 0, true); });
  el("camSide").addEventListener("click", function () { setCam(Math.PI / 2, 0, true); });
  document.addEventListener("keydown", function (e) {
    var tag = e.target && e.target.tagName, type = e.target && e.target.type;
    if (tag === "SELECT" || (tag === "INPUT" && type === "number")) return;  // their own keys
    if (e.key === " " && (tag === "BUTTON" || (tag === "INPUT" && type === "checkbox"))) return;  // their click
    if (e.key === "ArrowRight") { step(1); e.preventDefault(); }
    else if (e.key === "ArrowLeft") { step(-1); e.preventDefault(); }
    else if (e.key === " ") { playBtn.click(); e.preventDefault(); }
    else if (e.key === "Home") { step(-1e9); }
    else if (e.key === "End") { step(1e9); }
    else if (e.key === "r") { el("camReset").click(); }
    else if (e.key === "f") { el("camFront").click(); }
    else if (e.key === "s") { el("camSide").click(); }
    else if (e.key === "m" && audio) { el("sound").click(); }
  });

  function attachMouse(canvas) {
    var drag = null;
    canvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
    canvas.addEventListener("pointerdown", function (e) {
      drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button !== 0 };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", function (e) {
      if (!drag) return;
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) {
        var b = basis(), k = cam.dist * 0.0025;
        for (var a = 0; a < 3; a++) cam.target[a] += (-dx * b.right[a] + dy * b.up[a]) * k;
      } else {
        cam.yaw -= dx * 0.008;
        cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + dy * 0.008));
      }
      dirty = true;
    });
    var end = function () { drag = null; };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    canvas.addEventListener("wheel", function (e) {
      e.preventDefault();
      cam.dist = Math.max(0.2, Math.min(100, cam.dist * Math.exp(e.deltaY * 0.001)));
      dirty = true;
    }, { passive: false });
  }
  window.addEventListener("resize", resize);
  window.addEventListener("hashchange", function () { location.reload(); });  // a new #t=... applies at once

  // ---------------------------------------------------------------- loop
  var prev = null;
  function tick(now) {
    if (state.playing) {
      // the audio clock leads while the speech plays; otherwise the wall clock (times the speed)
      var audioLeads = audio && !audio.paused && !audio.ended && audio.readyState >= 2;
      var t = audioLeads ? audio.currentTime
        : state.t + (prev === null ? 0 : Math.min(0.25, (now - prev) / 1000) * state.speed);
      state.clock = audioLeads ? "audio" : "wall";
      state.audioTime = audioLeads ? t : null;
      if (t >= lastTime && (audioLeads || t > lastTime)) {
        state.clock = "wall"; state.audioTime = null;
        if (state.loop) { t = 0; audioSeek(0); } else { t = lastTime; state.playing = false; }
        state.t = t;
        audioSync();  // paused at the end, or playing again from the start
      }
      state.t = t;
      dirty = true;
    }
    prev = now;
    if (dirty) { dirty = false; draw(); }
    requestAnimationFrame(tick);
  }

  window.jaxgestViewer = {
    info: info,
    setTime: function (t) { setPlaying(false); setTime(t); draw(); dirty = false; return info(); },
    play: function () { setPlaying(true); },
    pause: function () { setPlaying(false); },
    audio: audio,
    position: function (k, f, j) { return P(clips[k], f, j); },
    camera: cam
  };
  buildPanels();
  audioSeek(state.t);
  audioSync();
  draw();
  dirty = false;
  requestAnimationFrame(tick);
})();
