(function () {
  "use strict";
  const D = JSON.parse(document.getElementById("replay-data").textContent);
  const bytes = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const f32 = (b64) => new Float32Array(bytes(b64).buffer);
  const i32 = (b64) => new Int32Array(bytes(b64).buffer);
  const viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
  for (const c of D.commands) viewer.handle_command_bytearray(bytes(c));
  const node = (p) => viewer.scene_tree.find(p.split("/"));
  const object = (p) => node("meshcat/replay/" + p + "/<object>").object;

  const F = D.frames, J = D.joints.length, N = D.horizon_n;
  const poses = f32(D.poses), poi = f32(D.poi), horizons = f32(D.horizons);
  const hindex = i32(D.horizon_index), scount = i32(D.sample_counts);
  const groups = D.joints.map((name) => node("meshcat/replay/arm/" + name).object);
  const poiMarker = node("meshcat/replay/poi").object;
  const toolMarker = node("meshcat/replay/arm/" + D.tool_joint + "/tool").object;
  const fLine = object("forecast/line"), fPoints = object("forecast/points");
  fPoints.geometry = fLine.geometry;
  const wholes = [];
  const trails = ["poi path", "tool path"].map((name) => {
    const whole = object(name + "/whole"), trail = object(name + "/trail");
    trail.geometry.setAttribute("position", whole.geometry.attributes.position);
    whole.frustumCulled = trail.frustumCulled = false;
    wholes.push(whole);
    return trail;
  });
  const samples = D.sample_counts && viewer.scene_tree.find(["meshcat", "replay"]).children
    .samples ? object("samples") : null;
  for (const o of [fLine, fPoints]) o.frustumCulled = false;

  const slider = document.getElementById("slider"), clock = document.getElementById("clock");
  const playButton = document.getElementById("play");
  slider.max = F - 1;
  const state = { frame: -1, time: D.t0, playing: true, speed: 1, shown: 0, view: "follow" };
  const cam = viewer.camera, controls = viewer.controls;
  // three.js is y-up, the scene z-up: (x, y, z) -> (x, z, -y)
  const up = (p) => [p[0], p[2], -p[1]];

  function follow(f) {
    // the camera rides with the POI: target and camera move by the POI's step
    const t = up([poi[3 * f], poi[3 * f + 1], poi[3 * f + 2]]);
    const dx = t[0] - controls.target.x, dy = t[1] - controls.target.y;
    const dz = t[2] - controls.target.z;
    controls.target.set(t[0], t[1], t[2]);
    cam.position.set(cam.position.x + dx, cam.position.y + dy, cam.position.z + dz);
  }
  function markers() {
    // the POI's and the tool's spheres keep their size on the screen: 1.2 % of the distance
    const s = 0.012 * cam.position.distanceTo(controls.target) / D.marker;
    for (const m of [poiMarker, toolMarker]) m.scale.set(s, s, s);
  }

  function show(f) {
    state.frame = f;
    for (let j = 0; j < J; j++) {
      const o = (f * J + j) * 7;
      groups[j].position.set(poses[o], poses[o + 1], poses[o + 2]);
      groups[j].quaternion.set(poses[o + 3], poses[o + 4], poses[o + 5], poses[o + 6]);
    }
    poiMarker.position.set(poi[3 * f], poi[3 * f + 1], poi[3 * f + 2]);
    if (state.view === "follow") follow(f);
    markers();
    const h = hindex[f];
    fLine.visible = fPoints.visible = h >= 0 && N > 0;
    if (fLine.visible) {
      const attr = fLine.geometry.attributes.position;
      attr.array.set(horizons.subarray(h * N * 3, (h + 1) * N * 3));
      attr.needsUpdate = true;
    }
    const end = f * D.path_per_frame + 1, start = Math.max(0, end - D.trail * D.path_per_frame);
    for (const t of trails) t.geometry.setDrawRange(start, end - start);
    if (samples) {
      const first = scount[Math.max(0, f - D.trail)];
      samples.geometry.setDrawRange(first, scount[f] - first);
    }
    slider.value = f;
    clock.textContent = "t = " + (D.t0 + f / D.fps).toFixed(3) + " s";
    state.shown += 1;
    viewer.set_dirty();
  }

  function setPlaying(on) {
    state.playing = on;
    playButton.textContent = on ? "Pause" : "Play";
  }
  function seek(f) {
    f = Math.max(0, Math.min(F - 1, f | 0));
    state.time = D.t0 + f / D.fps;
    show(f);
  }
  let last = null;
  function step(now) {
    if (state.playing && last !== null) {
      const span = (F - 1) / D.fps;
      state.time += Math.min(0.5, (now - last) / 1000) * state.speed;
      if (state.time > D.t0 + span) state.time = D.t0 + (span > 0 ? (state.time - D.t0) % span : 0);
    }
    last = now;
    const f = Math.min(F - 1, Math.max(0, Math.floor((state.time - D.t0) * D.fps + 1e-6)));
    if (f !== state.frame) show(f);
    requestAnimationFrame(step);
  }

  function look(target, span, dir) {
    const d = Math.max(span, 1e-4);
    const n = Math.hypot(dir[0], dir[1], dir[2]);
    const p = up(target.map((v, k) => v + d * dir[k] / n)), t = up(target);
    cam.near = Math.max(1e-5, d / 200);
    cam.position.set(p[0], p[1], p[2]);
    controls.target.set(t[0], t[1], t[2]);
    controls.update();
    markers();
    viewer.set_dirty();
  }
  const VIEWS = {
    follow: () => {
      const f = Math.max(0, state.frame);
      look([poi[3 * f], poi[3 * f + 1], poi[3 * f + 2]], D.follow, D.near_dir);
    },
    path: () => look(D.centre, Math.max(1.2 * D.poi_span, 0.005), D.near_dir),
    arm: () => look(D.arm_centre, 1.4 * D.arm_span, [0.6, -1.6, 0.5]),
  };
  function view(name) {
    state.view = name;
    for (const w of wholes) w.visible = name !== "follow";  // follow: the last second only
    for (const v of Object.keys(VIEWS)) {
      document.getElementById("view-" + v).classList.toggle("on", v === name);
    }
    VIEWS[name]();
  }

  playButton.onclick = () => setPlaying(!state.playing);
  slider.oninput = () => { setPlaying(false); seek(+slider.value); };
  document.getElementById("speed").onchange = (e) => { state.speed = +e.target.value; };
  for (const v of Object.keys(VIEWS)) {
    document.getElementById("view-" + v).onclick = () => view(v);
  }
  const help = document.getElementById("help");
  document.getElementById("help-button").onclick = () => { help.hidden = !help.hidden; };
  document.addEventListener("keydown", (e) => {
    if (e.code === "Space") { e.preventDefault(); setPlaying(!state.playing); }
  });
  window.replay = { state, seek, view, play: () => setPlaying(true),
                    pause: () => setPlaying(false), viewer };
  // the address may say where to start (the help panel lists it): page.html#t=2.5 (seconds of
  // the run; default the end of the settling span), &paused, &path or &arm (the view)
  const hash = new URLSearchParams(location.hash.slice(1));
  seek(Math.round(((hash.has("t") ? +hash.get("t") : D.start) - D.t0) * D.fps));
  view(hash.has("arm") ? "arm" : hash.has("path") ? "path" : "follow");
  if (hash.has("paused")) setPlaying(false);
  requestAnimationFrame(step);
})();
