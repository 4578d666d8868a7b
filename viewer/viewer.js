// The omnisculpt viewer: a classic script (no ES modules, no fetch), so that the page works
// when opened from the file system. Its data are scripts that assign globals:
// window.OMNI_SCENE (data/scene.js) and window.OMNI_DATA[key] (base64 .glb files, data/*.js;
// the snapshots are loaded on demand by inserting their script).
(function () {
  'use strict';

  const scene_data = window.OMNI_SCENE;
  const $ = (id) => document.getElementById(id);
  function Fail(message) {
    $('status').textContent = 'error: ' + message;
    console.error('omnisculpt viewer: ' + message);
  }
  if (typeof THREE === 'undefined' || !THREE.GLTFLoader || !THREE.OrbitControls) {
    Fail('three.js did not load (lib/)');
    return;
  }
  if (!scene_data || !window.OMNI_DATA || !window.OMNI_DATA[scene_data.surface.data]) {
    Fail('the data did not load (data/scene.js, data/surface.js)');
    return;
  }

  // ---- Renderer, scene, camera -------------------------------------------------------------
  const canvas = $('canvas');
  const renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const background = new THREE.Color(0x14171d);
  renderer.setClearColor(background);
  const world = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(60, 1, 0.05, 10000);
  camera.up.set(0, 0, 1);  // the reconstruction's world is z up
  world.add(camera);
  world.add(new THREE.AmbientLight(0xffffff, 0.55));
  const head_light = new THREE.DirectionalLight(0xffffff, 0.6);
  head_light.position.set(0.3, 0.5, 1);
  camera.add(head_light);

  const orbit = new THREE.OrbitControls(camera, canvas);
  orbit.enableDamping = false;
  orbit.screenSpacePanning = true;

  // ---- Materials ---------------------------------------------------------------------------
  const vertex_material = new THREE.MeshPhongMaterial({
    vertexColors: true, flatShading: true, shininess: 0, side: THREE.FrontSide });
  // The paper's Fig. 4 colouring (eval/render.h NormalColor): horizontal faces white, walls
  // coloured by the direction of their horizontal normal, shaded by |n . view|.
  const normal_material = new THREE.ShaderMaterial({
    side: THREE.FrontSide,
    vertexShader: [
      'varying vec3 v_world;',
      'void main() {',
      '  vec4 w = modelMatrix * vec4(position, 1.0);',
      '  v_world = w.xyz;',
      '  gl_Position = projectionMatrix * viewMatrix * w;',
      '}'].join('\n'),
    fragmentShader: [
      'varying vec3 v_world;',
      'vec3 hue_to_rgb(float h) {',
      '  h = 6.0 * fract(h);',
      '  return clamp(vec3(abs(h - 3.0) - 1.0, 2.0 - abs(h - 2.0), 2.0 - abs(h - 4.0)), 0.0, 1.0);',
      '}',
      'void main() {',
      '  vec3 n = normalize(cross(dFdx(v_world), dFdy(v_world)));',
      '  vec3 view = normalize(v_world - cameraPosition);',
      '  float shade = 0.25 + 0.75 * abs(dot(n, view));',
      '  vec3 rgb = abs(n.z) >= cos(radians(30.0)) ? vec3(1.0)',
      '      : hue_to_rgb(atan(n.y, n.x) / 6.28318530718 + 0.5);',
      '  gl_FragColor = vec4(shade * rgb, 1.0);',
      '}'].join('\n'),
  });
  const point_material = new THREE.PointsMaterial({ size: 2.5, sizeAttenuation: false,
                                                     vertexColors: true });

  // ---- Data ---------------------------------------------------------------------------------
  function GlbFromBase64(base64) {
    const bytes = atob(base64);
    const buffer = new Uint8Array(bytes.length);
    for (let i = 0; i < bytes.length; ++i) buffer[i] = bytes.charCodeAt(i);
    return buffer.buffer;
  }
  // Calls done({surface: BufferGeometry|null, points: BufferGeometry|null}).
  function ParseGlb(key, done) {
    new THREE.GLTFLoader().parse(GlbFromBase64(window.OMNI_DATA[key]), '', function (gltf) {
      const found = { surface: null, points: null };
      gltf.scene.traverse(function (object) {
        if (object.isMesh && object.parent && object.parent.name === 'surface') found.surface = object.geometry;
        else if (object.isMesh && object.name === 'surface') found.surface = object.geometry;
        if (object.isPoints) found.points = object.geometry;
      });
      done(found);
    }, function (error) { Fail('cannot read ' + key + ': ' + error); });
  }
  function LoadScript(file, done) {
    const script = document.createElement('script');
    script.src = file;
    script.onload = done;
    script.onerror = function () { Fail('cannot load ' + file); };
    document.body.appendChild(script);
  }

  const keyframes = scene_data.keyframes;
  const snapshots = scene_data.snapshots;
  const loops = scene_data.loop_closures;
  let final_geometry = null, points_object = null, surface_object = null;
  const snapshot_geometry = {};  // by snapshot index
  let current = snapshots.length;  // the slider's position; snapshots.length: the final surface

  // ---- Trajectory, keyframes, loop closures, the car ----------------------------------------
  const trajectory = new THREE.Group();
  world.add(trajectory);
  const centres = keyframes.map((k) => new THREE.Vector3(k.pose[0], k.pose[1], k.pose[2]));
  const path_geometry = new THREE.BufferGeometry().setFromPoints(centres);
  const path_line = new THREE.Line(path_geometry, new THREE.LineBasicMaterial({ color: 0xffd54f }));
  trajectory.add(path_line);
  let extent = 1;
  {
    const box = new THREE.Box3().setFromPoints(centres);
    extent = Math.max(1, box.getSize(new THREE.Vector3()).length());
  }
  const marker_radius = Math.max(0.08, extent * 0.004);
  // Keyframes and loop closures: round dots of a fixed size on the screen (a sphere of the
  // keyframe next to the camera would fill the view from a keyframe).
  const dot = (function () {
    const c = document.createElement('canvas');
    c.width = c.height = 32;
    const g = c.getContext('2d');
    g.fillStyle = '#ffffff';
    g.beginPath(); g.arc(16, 16, 14, 0, 2 * Math.PI); g.fill();
    return new THREE.CanvasTexture(c);
  })();
  const keyframe_markers = new THREE.Points(new THREE.BufferGeometry().setFromPoints(centres),
    new THREE.PointsMaterial({ color: 0xffd54f, size: 7, sizeAttenuation: false, map: dot,
                               alphaTest: 0.5, transparent: false }));
  trajectory.add(keyframe_markers);
  const loop_markers = [];
  loops.forEach(function (loop, i) {
    const a = centres[loop.keyframe], b = centres[loop.candidate_keyframe];
    if (!a) return;
    const marker = new THREE.Points(new THREE.BufferGeometry().setFromPoints([a]),
      new THREE.PointsMaterial({ color: 0xe5484d, size: 16, sizeAttenuation: false, map: dot,
                                 alphaTest: 0.5 }));
    marker.userData.loop = i;
    marker.renderOrder = 1;
    trajectory.add(marker);
    loop_markers.push(marker);
    if (b) {
      const link = new THREE.Line(new THREE.BufferGeometry().setFromPoints([a, b]),
                                  new THREE.LineDashedMaterial({ color: 0xe5484d, dashSize: marker_radius * 4,
                                                                 gapSize: marker_radius * 2 }));
      link.computeLineDistances();
      trajectory.add(link);
    }
  });
  // The car: a box along the rig's x axis, at the keyframe of the snapshot shown.
  const car = new THREE.Mesh(new THREE.BoxGeometry(marker_radius * 12, marker_radius * 6, marker_radius * 4),
                             new THREE.MeshPhongMaterial({ color: 0x26c6da, flatShading: true }));
  world.add(car);
  function PlaceCar(k) {
    const p = keyframes[k].pose;
    car.position.set(p[0], p[1], p[2]);
    car.quaternion.set(p[3], p[4], p[5], p[6]);
  }

  // ---- The surface shown ---------------------------------------------------------------------
  function SurfaceMaterial() { return $('coloring').value === 'normal' ? normal_material : vertex_material; }
  function ShowGeometry(geometry, triangles) {
    if (!surface_object) {
      surface_object = new THREE.Mesh(geometry, SurfaceMaterial());
      world.add(surface_object);
    }
    surface_object.geometry = geometry;
    surface_object.visible = $('show-surface').checked;
    $('triangle-count').textContent = String(triangles);
  }
  function KeyframeOfPosition(i) {
    return i >= snapshots.length ? keyframes.length - 1
                                 : Math.min(snapshots[i].keyframe, keyframes.length - 1);
  }
  function LoopsBefore(keyframe) { return loops.filter((l) => l.keyframe <= keyframe).length; }
  function ShowPosition(i) {
    current = i;
    const k = KeyframeOfPosition(i);
    PlaceCar(k);
    path_geometry.setDrawRange(0, k + 1);
    keyframe_markers.geometry.setDrawRange(0, k + 1);
    loop_markers.forEach((m) => { m.visible = loops[m.userData.loop].keyframe <= k; });
    if (points_object) {
      const n = i >= snapshots.length ? scene_data.surface.points : keyframes[k].points;
      points_object.geometry.setDrawRange(0, n);
      $('point-count').textContent = String(n);
    }
    const closures = LoopsBefore(k);
    const replayed = closures > 0 && (i === 0 ? true : LoopsBefore(KeyframeOfPosition(i - 1)) < closures);
    $('replay-badge').hidden = !(replayed && i < snapshots.length);
    let label;
    if (i >= snapshots.length) {
      label = 'final observed surface (surface.ply), ' + keyframes.length + ' keyframes';
    } else {
      const s = snapshots[i];
      label = 'snapshot ' + (i + 1) + ' of ' + snapshots.length + ': after keyframe ' + s.keyframe +
              ' (frame ' + keyframes[k].frame + '): ' +
              (s.observed ? 'the observed surface of δO, ' + s.triangles + ' triangles'
                          : 'δO, ' + s.triangles + ' of its ' + s.closed_triangles +
                                ' triangles (those with a Steiner vertex left out)');
    }
    if (closures > 0) label += '\n' + closures + ' loop closure' + (closures > 1 ? 's' : '') + ' so far' +
                              (replayed && i < snapshots.length ? ': this snapshot follows the re-sculpting of the corrected map' : '');
    $('time-label').textContent = label;
    DrawPlot();
    if (i >= snapshots.length) {
      ShowGeometry(final_geometry, scene_data.surface.triangles);
      return;
    }
    if (snapshot_geometry[i]) {
      ShowGeometry(snapshot_geometry[i], snapshots[i].triangles);
      return;
    }
    $('status').textContent = 'loading snapshot…';
    const s = snapshots[i];
    const parse = function () {
      ParseGlb(s.data, function (found) {
        snapshot_geometry[i] = found.surface;
        $('status').textContent = 'ready';
        if (current === i) ShowGeometry(found.surface, s.triangles);
      });
    };
    if (window.OMNI_DATA[s.data]) parse(); else LoadScript(s.file, parse);
  }

  // ---- Camera placement and controls ----------------------------------------------------------
  let surface_box = new THREE.Box3();
  function Overview() {
    SetNavigation('orbit');
    const centre = surface_box.getCenter(new THREE.Vector3());
    const size = Math.max(1, surface_box.getSize(new THREE.Vector3()).length());
    camera.fov = 50;
    camera.position.set(centre.x - 0.25 * size, centre.y - 0.55 * size, centre.z + 0.6 * size);
    camera.near = size / 2000;
    camera.far = size * 20;
    camera.updateProjectionMatrix();
    orbit.target.copy(centre);
    orbit.update();
  }
  function ViewFromKeyframe(k, c) {
    const cam = scene_data.cameras[c];
    let pose;
    if (cam && cam.poses[k]) {
      pose = cam.poses[k];
      camera.fov = cam.fov_y_deg;
    } else {  // no camera model: the rig's pose, looking along its x axis
      const p = keyframes[k].pose;
      const q = new THREE.Quaternion(p[3], p[4], p[5], p[6]).multiply(
        new THREE.Quaternion().setFromEuler(new THREE.Euler(Math.PI / 2, -Math.PI / 2, 0, 'YXZ')));
      pose = [p[0], p[1], p[2], q.x, q.y, q.z, q.w];
      camera.fov = 70;
    }
    SetNavigation('fly');
    camera.position.set(pose[0], pose[1], pose[2]);
    camera.quaternion.set(pose[3], pose[4], pose[5], pose[6]);
    camera.near = 0.05;
    camera.updateProjectionMatrix();
    const euler = new THREE.Euler().setFromQuaternion(camera.quaternion, 'ZXY');
    fly.yaw = euler.z; fly.pitch = euler.x; fly.roll = euler.y;
  }

  // Fly: drag to look (yaw about the world's z), W A S D / arrows to move, Q E down / up.
  const fly = { yaw: 0, pitch: Math.PI / 2, roll: 0, keys: {}, dragging: false, x: 0, y: 0 };
  function SetNavigation(mode) {
    $('navigation').value = mode;
    orbit.enabled = mode === 'orbit';
    if (mode === 'fly') {
      const euler = new THREE.Euler().setFromQuaternion(camera.quaternion, 'ZXY');
      fly.yaw = euler.z; fly.pitch = euler.x; fly.roll = euler.y;
    } else {
      const forward = new THREE.Vector3(0, 0, -1).applyQuaternion(camera.quaternion);
      orbit.target.copy(camera.position).addScaledVector(forward, Math.max(2, extent * 0.05));
      orbit.update();
    }
  }
  function FlyOrientation() {
    camera.quaternion.setFromEuler(new THREE.Euler(fly.pitch, fly.roll, fly.yaw, 'ZXY'));
  }
  canvas.addEventListener('pointerdown', function (e) {
    fly.dragging = true; fly.x = e.clientX; fly.y = e.clientY; fly.moved = 0;
  });
  window.addEventListener('pointerup', function (e) {
    if (fly.dragging && fly.moved < 4) Pick(e);
    fly.dragging = false;
  });
  window.addEventListener('pointermove', function (e) {
    if (!fly.dragging) return;
    const dx = e.clientX - fly.x, dy = e.clientY - fly.y;
    fly.moved += Math.abs(dx) + Math.abs(dy);
    fly.x = e.clientX; fly.y = e.clientY;
    if ($('navigation').value !== 'fly') return;
    fly.roll = 0;
    fly.yaw -= dx * 0.004;
    fly.pitch = Math.min(Math.PI - 0.01, Math.max(0.01, fly.pitch - dy * 0.004));
    FlyOrientation();
  });
  window.addEventListener('keydown', function (e) {
    if (e.target.tagName === 'INPUT' && e.target.type === 'number') return;
    fly.keys[e.key.toLowerCase()] = true;
  });
  window.addEventListener('keyup', function (e) { fly.keys[e.key.toLowerCase()] = false; });
  let last_time = performance.now();
  function MoveFly(seconds) {
    if ($('navigation').value !== 'fly') return;
    const k = fly.keys;
    const speed = (k.shift ? 4 : 1) * Math.max(2, extent * 0.08) * seconds;
    const forward = new THREE.Vector3(0, 0, -1).applyQuaternion(camera.quaternion);
    const right = new THREE.Vector3(1, 0, 0).applyQuaternion(camera.quaternion);
    if (k.w || k.arrowup) camera.position.addScaledVector(forward, speed);
    if (k.s || k.arrowdown) camera.position.addScaledVector(forward, -speed);
    if (k.d || k.arrowright) camera.position.addScaledVector(right, speed);
    if (k.a || k.arrowleft) camera.position.addScaledVector(right, -speed);
    if (k.e) camera.position.z += speed;
    if (k.q) camera.position.z -= speed;
  }

  // ---- Picking keyframes and loop closures ------------------------------------------------------
  // The keyframe or loop closure drawn nearest to the click, within 10 pixels (loop closures
  // first).
  function Pick(e) {
    if (!$('show-trajectory').checked) return;
    const rect = canvas.getBoundingClientRect();
    const x = e.clientX - rect.left, y = e.clientY - rect.top;
    const shown = keyframe_markers.geometry.drawRange.count;
    const on_screen = function (p) {
      const v = p.clone().project(camera);
      if (v.z < -1 || v.z > 1) return Infinity;
      return Math.hypot((v.x + 1) / 2 * rect.width - x, (1 - v.y) / 2 * rect.height - y);
    };
    let best = null, best_distance = 10;
    loop_markers.forEach(function (m) {
      if (!m.visible) return;
      const d = on_screen(centres[loops[m.userData.loop].keyframe]);
      if (d < best_distance) { best_distance = d; best = { loop: m.userData.loop }; }
    });
    if (best) { SelectLoop(best.loop); return; }
    centres.forEach(function (c, k) {
      if (k >= shown) return;
      const d = on_screen(c);
      if (d < best_distance) { best_distance = d; best = { keyframe: k }; }
    });
    if (best) SelectKeyframe(best.keyframe);
  }
  // For tests and the console: where keyframe k is drawn, in CSS pixels of the page.
  function ScreenPosition(k) {
    const rect = canvas.getBoundingClientRect();
    const v = centres[k].clone().project(camera);
    return { x: rect.left + (v.x + 1) / 2 * rect.width, y: rect.top + (1 - v.y) / 2 * rect.height };
  }
  function SelectKeyframe(k) {
    const kf = keyframes[k];
    $('view-keyframe').value = k;
    $('selection').textContent = 'keyframe ' + k + ', frame ' + kf.frame + ', t = ' + kf.time.toFixed(2) +
      ' s\ncentre (' + kf.pose.slice(0, 3).map((v) => v.toFixed(2)).join(', ') + ')\n' +
      kf.points + ' points observed by keyframes ≤ ' + k;
  }
  function SelectLoop(i) {
    const l = loops[i];
    $('selection').textContent = 'loop closure ' + (i + 1) + ': keyframe ' + l.keyframe + ' (frame ' + l.frame +
      ') revisits keyframe ' + l.candidate_keyframe + ' (frame ' + l.candidate_frame + ')\n' +
      'correction: ' + Number(l.correction_translation).toFixed(3) + ' (map units), ' +
      Number(l.correction_rotation_deg).toFixed(2) + '°, scale ' + Number(l.correction_scale).toFixed(4) + '\n' +
      'inliers ' + l.inliers + ' of ' + l.matches + ' matches; surface replay ' +
      Number(l.surface_replay_seconds || 0).toFixed(2) + ' s over ' + (l.surface_replay_keyframes || 0) + ' keyframes';
  }

  // ---- The time plot of stats/keyframes.csv -------------------------------------------------
  const rows = [];
  {
    const lines = (scene_data.keyframes_csv || '').trim().split('\n');
    const header = lines.length ? lines[0].split(',') : [];
    const col = (name) => header.indexOf(name);
    const ck = col('keyframe'), cb = col('batch'), cm = col('ms_total'), cr = col('replay');
    const cn = col('keyframes');  // keyframes sculpted in the row's step: ms per keyframe
    for (let i = 1; i < lines.length; ++i) {
      const f = lines[i].split(',');
      if (ck < 0 || cm < 0) break;
      rows.push({ keyframe: +f[ck], batch: cb >= 0 && +f[cb] > 0, ms: +f[cm] / (cn >= 0 ? Math.max(1, +f[cn]) : 1), replay: cr >= 0 ? +f[cr] : 0 });
    }
  }
  function DrawPlot() {
    const plot = $('plot');
    const g = plot.getContext('2d');
    const w = plot.width, h = plot.height, left = 34, bottom = 18, top = 6;
    g.clearRect(0, 0, w, h);
    g.font = '10px sans-serif';
    g.fillStyle = '#9aa3b2';
    if (!rows.length) { g.fillText('no stats/keyframes.csv', left, h / 2); return; }
    const max_k = Math.max(keyframes.length - 1, ...rows.map((r) => r.keyframe));
    const max_ms = Math.max(1, ...rows.map((r) => r.ms));
    const x = (k) => left + (w - left - 4) * (k / Math.max(1, max_k));
    const y = (ms) => h - bottom - (h - bottom - top) * (ms / max_ms);
    g.strokeStyle = '#3a414d';
    g.beginPath(); g.moveTo(left, top); g.lineTo(left, h - bottom); g.lineTo(w - 2, h - bottom); g.stroke();
    g.fillText(max_ms.toFixed(0) + ' ms', 2, top + 8);
    g.fillText('0', left - 10, h - bottom);
    g.fillText('keyframe', w / 2 - 20, h - 4);
    g.fillText(String(max_k), w - 18, h - 6);
    const bar = Math.max(1.5, (w - left) / Math.max(1, rows.length) * 0.7);
    rows.forEach(function (r) {
      g.fillStyle = r.replay > 0 ? '#f0a33c' : r.batch ? '#9b7fd1' : '#4f9bd9';
      g.fillRect(x(r.keyframe) - bar / 2, y(r.ms), bar, h - bottom - y(r.ms));
    });
    g.strokeStyle = '#e5484d';
    loops.forEach(function (l) { g.beginPath(); g.moveTo(x(l.keyframe), top); g.lineTo(x(l.keyframe), h - bottom); g.stroke(); });
    const k = KeyframeOfPosition(current);
    g.strokeStyle = '#ffffff';
    g.setLineDash([3, 3]);
    g.beginPath(); g.moveTo(x(k), top); g.lineTo(x(k), h - bottom); g.stroke();
    g.setLineDash([]);
  }

  // ---- The page's controls ----------------------------------------------------------------------
  const slider = $('time-slider');
  slider.max = String(snapshots.length);
  slider.value = String(snapshots.length);
  slider.disabled = snapshots.length === 0;
  slider.addEventListener('input', () => ShowPosition(+slider.value));
  let playing = null;
  function StopPlaying() { clearInterval(playing); playing = null; $('play').innerHTML = '&#9654;'; }
  $('play').disabled = snapshots.length === 0;
  $('play').addEventListener('click', function () {
    if (playing) { StopPlaying(); return; }
    if (+slider.value >= snapshots.length) { slider.value = '0'; ShowPosition(0); }
    $('play').innerHTML = '&#10074;&#10074;';
    playing = setInterval(function () {
      if (+slider.value >= snapshots.length) { StopPlaying(); return; }
      slider.value = String(+slider.value + 1);
      ShowPosition(+slider.value);
    }, 800);
  });
  $('coloring').addEventListener('change', function () { if (surface_object) surface_object.material = SurfaceMaterial(); });
  $('show-surface').addEventListener('change', function () { if (surface_object) surface_object.visible = this.checked; });
  $('show-points').addEventListener('change', function () { if (points_object) points_object.visible = this.checked; });
  $('show-trajectory').addEventListener('change', function () { trajectory.visible = this.checked; });
  $('navigation').addEventListener('change', function () { SetNavigation(this.value); });
  $('overview').addEventListener('click', Overview);
  const camera_select = $('view-camera');
  (scene_data.cameras.length ? scene_data.cameras.map((c) => c.name) : ['rig']).forEach(function (name, i) {
    const option = document.createElement('option');
    option.value = String(i);
    option.textContent = name;
    camera_select.appendChild(option);
  });
  $('view-keyframe').max = String(keyframes.length - 1);
  $('view-from-keyframe').addEventListener('click', function () {
    const k = Math.max(0, Math.min(keyframes.length - 1, Math.round(+$('view-keyframe').value || 0)));
    $('view-keyframe').value = k;
    ViewFromKeyframe(k, +camera_select.value);
    SelectKeyframe(k);
  });

  $('title').textContent = scene_data.title;
  {
    const r = scene_data.run || {};
    const parts = [];
    if (r.status) parts.push(r.status);
    if (r.frames) parts.push(r.frames + ' frames');
    parts.push(keyframes.length + ' keyframes', scene_data.surface.points + ' points',
               scene_data.surface.triangles + ' triangles', snapshots.length + ' snapshots',
               loops.length + ' loop closure' + (loops.length === 1 ? '' : 's'));
    $('run').textContent = parts.join(' · ');
  }

  function Resize() {
    const view = $('view');
    renderer.setSize(view.clientWidth, view.clientHeight, false);
    camera.aspect = view.clientWidth / Math.max(1, view.clientHeight);
    camera.updateProjectionMatrix();
  }
  window.addEventListener('resize', Resize);

  let frames_drawn = 0;
  function Animate(now) {
    MoveFly(Math.min(0.1, (now - last_time) / 1000));
    last_time = now;
    if (orbit.enabled) orbit.update();
    renderer.render(world, camera);
    ++frames_drawn;
    if (frames_drawn === 2 && final_geometry) {
      document.body.dataset.ready = '1';
      $('status').textContent = 'ready';
    }
    requestAnimationFrame(Animate);
  }

  ParseGlb(scene_data.surface.data, function (found) {
    if (!found.surface) { Fail('the surface .glb holds no triangle mesh'); return; }
    final_geometry = found.surface;
    final_geometry.computeBoundingBox();
    surface_box = final_geometry.boundingBox.clone();
    if (found.points) {
      points_object = new THREE.Points(found.points, point_material);
      world.add(points_object);
    }
    Resize();
    ShowPosition(snapshots.length);
    Overview();
    // For tests and the console: the page's state.
    window.omniViewer = { frames: () => frames_drawn, position: () => current, screenPosition: ScreenPosition,
                          loopKeyframes: () => loops.map((l) => l.keyframe) };
    requestAnimationFrame(Animate);
  });
})();
