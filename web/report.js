// inhand scan report: the model coloured by confidence, the views as frusta, the held hands, the
// per-view curves and the ranked grasp candidates. Data: window.INHAND_DATA (see html_report.cc).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/OrbitControls.js';
import { GLTFLoader } from 'three/addons/GLTFLoader.js';

const D = window.INHAND_DATA;
const S = D.summary;
const state = { charts: {}, ready: false };
window.inhandReport = state;

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'style') e.style.cssText = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
}
const fmt = (x, d = 3) => (typeof x === 'number' && isFinite(x) ? x.toFixed(d) : '–');

function decode(b64, Type) {
  const bin = atob(b64);
  const u8 = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; ++i) u8[i] = bin.charCodeAt(i);
  return new Type(u8.buffer);
}

function geometryOf(m) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(decode(m.positions, Float32Array), 3));
  g.setIndex(new THREE.BufferAttribute(decode(m.indices, Uint32Array), 1));
  if (m.colors) g.setAttribute('color', new THREE.BufferAttribute(decode(m.colors, Uint8Array), 3, true));
  if (m.confidence_colors) {  // scanned with colour: both colourings, the report's switch picks
    g.userData.scanColour = g.getAttribute('color');
    g.userData.confidenceColour = new THREE.BufferAttribute(decode(m.confidence_colors, Uint8Array), 3, true);
  }
  g.computeVertexNormals();
  return g;
}

function modelMesh(m) {
  const mat = new THREE.MeshLambertMaterial({ vertexColors: !!m.colors, color: m.colors ? 0xffffff : 0xaaaaaa,
                                              side: THREE.DoubleSide });
  return new THREE.Mesh(geometryOf(m), mat);
}
function handMesh(m, opacity = 0.55) {
  return new THREE.Mesh(geometryOf(m), new THREE.MeshLambertMaterial({
    color: 0x4a6fa5, transparent: true, opacity, depthWrite: false }));
}
function rowMajor(a) {
  const M = new THREE.Matrix4();
  M.set(...a);
  return M;
}

// ---- header and summary -------------------------------------------------------------------
const app = document.getElementById('app');
const cov = S.coverage !== undefined ? `, coverage ${(100 * S.coverage).toFixed(1)}% of the true surface` : '';
app.append(el('header', {}, el('h1', {}, `inhand scan of ${S.object}`),
  el('div', {}, `${S.grasps.length} grasp(s), ${S.views.length} views, ended: ${S.termination}${cov}; ` +
                `planner ${S.planner || 'ig'}, seed ${S.seed}`)));
const main = el('main');
app.append(main);

// ---- 3-D viewer -----------------------------------------------------------------------------
const viewerSection = el('section', { id: 'model' }, el('h2', {}, 'Model'));
main.append(viewerSection);
const controlsDiv = el('div', { class: 'controls' });
viewerSection.append(controlsDiv);
const canvas = el('canvas', { id: 'viewer' });
viewerSection.append(canvas);
viewerSection.append(el('div', { class: 'legend' }, 'Colour by confidence:',
  el('span', { style: 'background:#999' }), 'confident (σ small)',
  el('span', { style: 'background:#e08080' }), 'uncertain',
  el('span', { style: 'background:#d00' }), 'never seen (hole-filled, σ = 5 cm)',
  el('span', { style: 'background:#4a6fa5' }), 'hand holding it',
  el('span', { style: 'background:#2a2' }), 'true surface',
  '  Camera frusta: numbered in the order taken, drawn at 45% of their 0.7 m range.'));

const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf2f2f2);
scene.add(new THREE.AmbientLight(0xffffff, 1.2));
const camera = new THREE.PerspectiveCamera(35, 2, 0.005, 20);
const headlight = new THREE.DirectionalLight(0xffffff, 2.0);
camera.add(headlight);
scene.add(camera);

const models = [];  // {label, mesh, hand}
const finalMesh = modelMesh(D.model);
const box = new THREE.Box3().setFromObject(finalMesh);
const centre = box.getCenter(new THREE.Vector3());
const radius = Math.max(0.05, box.getSize(new THREE.Vector3()).length() / 2);
D.grasps.forEach((g, i) => {
  const hand = g.hand ? handMesh(g.hand) : null;
  if (g.model) models.push({ label: `after grasp ${i + 1}`, mesh: modelMesh(g.model), hand, grasp: i + 1 });
});
models.push({ label: 'final model', mesh: finalMesh,
              hand: D.grasps.length && D.grasps[D.grasps.length - 1].hand ? handMesh(D.grasps[D.grasps.length - 1].hand) : null,
              grasp: D.grasps.length });
const truth = D.truth ? new THREE.Mesh(geometryOf(D.truth), new THREE.MeshLambertMaterial({
  color: 0x22aa22, wireframe: true, transparent: true, opacity: 0.35 })) : null;
if (truth) scene.add(truth);

// Frusta.
const cam = S.camera || { width: 640, height: 480, fx: 525, fy: 525, cx: 319.5, cy: 239.5 };
const frusta = new THREE.Group();
const scale = 0.45;
function labelSprite(text, color) {
  const c = document.createElement('canvas');
  c.width = c.height = 64;
  const x = c.getContext('2d');
  x.fillStyle = color; x.beginPath(); x.arc(32, 32, 28, 0, 2 * Math.PI); x.fill();
  x.fillStyle = '#fff'; x.font = 'bold 30px sans-serif'; x.textAlign = 'center'; x.textBaseline = 'middle';
  x.fillText(text, 32, 34);
  const s = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(c), depthTest: false }));
  s.scale.set(0.025, 0.025, 1);
  return s;
}
const graspColors = ['#c0392b', '#2471a3', '#229954', '#b7950b', '#7d3c98', '#ca6f1e'];
S.views.forEach((v, i) => {
  if (!v.T_O_C) return;
  const M = rowMajor(v.T_O_C);
  const color = v.initial ? '#777777' : graspColors[((v.grasp || 1) - 1) % graspColors.length];
  const h = 0.05;
  const corners = [[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]].map(
    ([u, w]) => new THREE.Vector3((u - cam.cx) / cam.fx * h, (w - cam.cy) / cam.fy * h, h));
  const o = new THREE.Vector3();
  const pts = [];
  for (let k = 0; k < 4; ++k) pts.push(o, corners[k], corners[k], corners[(k + 1) % 4]);
  const g = new THREE.BufferGeometry().setFromPoints(pts);
  const lines = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color }));
  const group = new THREE.Group();
  group.add(lines);
  const lab = labelSprite(String(i + 1), color);
  lab.position.set(0, 0, -0.012);
  group.add(lab);
  // Pose: the camera frame, moved towards the object's centre to `scale` of its range.
  const pos = new THREE.Vector3().setFromMatrixPosition(M);
  const q = new THREE.Quaternion().setFromRotationMatrix(M);
  group.position.copy(centre.clone().add(pos.sub(centre).multiplyScalar(scale)));
  group.quaternion.copy(q);
  frusta.add(group);
});
scene.add(frusta);

let current = models[models.length - 1];
function show(m) {
  for (const x of models) { scene.remove(x.mesh); if (x.hand) scene.remove(x.hand); }
  current = m;
  scene.add(m.mesh);
  if (m.hand && handBox.checked) scene.add(m.hand);
  render();
}
const select = el('select', { onchange: () => show(models[+select.value]) });
models.forEach((m, i) => select.append(el('option', { value: i }, m.label)));
select.value = models.length - 1;
const truthBox = el('input', { type: 'checkbox', onchange: () => { if (truth) truth.visible = truthBox.checked; render(); } });
const viewsBox = el('input', { type: 'checkbox', checked: '', onchange: () => { frusta.visible = viewsBox.checked; render(); } });
const handBox = el('input', { type: 'checkbox', checked: '', onchange: () => show(current) });
// Scanned colour or confidence, on every model that has both.
const colourBox = el('input', { type: 'checkbox', checked: '', onchange: () => {
  for (const m of models) {
    if (!m.mesh.geometry) continue;  // the textured model keeps its texture
    const u = m.mesh.geometry.userData;
    if (u.scanColour) m.mesh.geometry.setAttribute('color', colourBox.checked ? u.scanColour : u.confidenceColour);
  }
  render();
} });
controlsDiv.append(el('label', {}, 'Show: ', select),
  el('label', {}, truthBox, ' true mesh' + (truth ? '' : ' (not known)')),
  el('label', {}, viewsBox, ' camera views'), el('label', {}, handBox, ' hand'));
if (D.model.confidence_colors) controlsDiv.append(el('label', {}, colourBox, ' scanned colour (off: confidence)'));
if (!truth) truthBox.disabled = true; else truth.visible = false;

camera.position.copy(centre.clone().add(new THREE.Vector3(1.2, -1.6, 1.0).normalize().multiplyScalar(radius * 5.5)));
camera.up.set(0, 0, 1);
const controls = new OrbitControls(camera, canvas);
controls.target.copy(centre);
controls.update();
function render() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) || canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  renderer.render(scene, camera);
}
controls.addEventListener('change', render);
window.addEventListener('resize', render);
show(current);

// Fraction of the viewer's pixels that differ from the background (for the browser test).
state.nonBackgroundFraction = () => {
  render();
  const c = document.createElement('canvas');
  c.width = canvas.width; c.height = canvas.height;
  const x = c.getContext('2d');
  x.drawImage(canvas, 0, 0);
  const px = x.getImageData(0, 0, c.width, c.height).data;
  let n = 0;
  for (let i = 0; i < px.length; i += 4)
    if (Math.abs(px[i] - 0xf2) > 8 || Math.abs(px[i + 1] - 0xf2) > 8 || Math.abs(px[i + 2] - 0xf2) > 8) ++n;
  return n / (px.length / 4);
};

// ---- curves ---------------------------------------------------------------------------------
const curves = el('section', { id: 'curves' }, el('h2', {}, 'Per view'));
main.append(curves);
const chartRow = el('div', { class: 'row' });
curves.append(chartRow);
const labels = S.views.map((v, i) => `${i + 1}${v.initial ? 'i' : ''}`);
function chart(id, title, datasets, yTitle) {
  const box = el('div', { class: 'chart' });
  const c = el('canvas', { id });
  box.append(c);
  chartRow.append(box);
  const ch = new Chart(c, {
    type: 'line',
    data: { labels, datasets },
    options: { animation: false, responsive: true, maintainAspectRatio: false,
               plugins: { title: { display: true, text: title } },
               scales: { x: { title: { display: true, text: 'view (i: initial trajectory)' } },
                         y: { title: { display: true, text: yTitle } } } },
  });
  state.charts[id] = datasets.map((d) => d.data.length);
  return ch;
}
const ds = (label, data, color) => ({ label, data, borderColor: color, backgroundColor: color, pointRadius: 3, tension: 0 });
// Marks on the entropy curve (one entry per view, null where nothing happened): the views in
// which a slip of the object in the hand was found, and each grasp's last view where its views
// ended because the object was lost from the hand (a drop noticed in the frames).
const slips = S.slips_found || [];
const lostAfter = new Set();
S.grasps.forEach((g, gi) => {
  if (g.termination !== 'object_lost') return;
  let last = -1;
  // Views number grasps from 1.
  S.views.forEach((v, i) => { if (v.grasp === gi + 1) last = i; });
  if (last >= 0) lostAfter.add(last);
});
const mark = (label, at, color, style) => ({ label, data: S.views.map((v, i) => (at(i) ? v.mean_entropy : null)),
  borderColor: color, backgroundColor: color, pointRadius: 8, pointStyle: style, showLine: false });
chart('entropy', 'Mean entropy of the model (paper Fig. 5)', [ds('mean entropy, nats', S.views.map((v) => v.mean_entropy), '#c0392b'),
  mark('slip found in the hand', (i) => slips.some((e) => e.view === i), '#e67e22', 'triangle'),
  mark('object lost from the hand', (i) => lostAfter.has(i), '#000000', 'crossRot')], 'nats');
if (S.views.some((v) => v.coverage >= 0))
  chart('coverage', 'Coverage of the true surface (τ = 3 mm)', [ds('coverage %', S.views.map((v) => 100 * v.coverage), '#229954')], '%');
chart('quality', 'View quality (eq. 9) of each chosen view', [ds('quality (initial views: none)', S.views.map((v) => (v.initial ? null : v.quality)), '#2471a3')], 'quality');
chart('cost', 'Trajectory time to each view', [ds('cost, s', S.views.map((v) => v.cost_s), '#7d3c98'),
  ds('cumulative, s', S.views.map((v) => v.trajectory_s), '#b7950b')], 's');

// ---- grasps ---------------------------------------------------------------------------------
const gs = el('section', { id: 'grasps' }, el('h2', {}, 'Grasps'));
main.append(gs);
const gt = el('table');
gt.append(el('tr', {}, ...['grasp', 'candidates', 'quality', 'stability ε', 'views', 'ended', 'unknown area m²', 'mean entropy']
  .map((h) => el('th', {}, h))));
S.grasps.forEach((g, i) => gt.append(el('tr', {}, el('td', {}, i + 1), el('td', {}, g.candidates),
  el('td', {}, fmt(g.quality, 4)), el('td', {}, fmt(g.stability_epsilon, 4)), el('td', {}, g.views),
  el('td', {}, g.termination), el('td', {}, fmt(g.unknown_area_m2, 4)), el('td', {}, fmt(g.mean_entropy, 3)))));
gs.append(gt);
// Candidates (paper Fig. 6b): each drawn small on the model they were ranked on, best first.
const thumbR = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
thumbR.setSize(170, 170);
D.grasps.forEach((g, i) => {
  const meta = (S.grasps[i] && S.grasps[i].ranked) || [];
  if (!g.candidates || !g.candidates.length || i === 0) return;
  const on = D.grasps[i - 1] && D.grasps[i - 1].model ? modelMesh(D.grasps[i - 1].model) : finalMesh.clone();
  gs.append(el('h3', {}, `Grasp ${i + 1}: the best ${g.candidates.length} of ${S.grasps[i].candidates} candidates, by view quality`));
  const row = el('div', { class: 'thumbs' });
  gs.append(row);
  g.candidates.forEach((c, j) => {
    const ts = new THREE.Scene();
    ts.background = new THREE.Color(0xffffff);
    ts.add(new THREE.AmbientLight(0xffffff, 1.2));
    const tc = new THREE.PerspectiveCamera(35, 1, 0.005, 20);
    tc.up.set(0, 0, 1);
    tc.position.copy(centre.clone().add(new THREE.Vector3(1.2, -1.6, 1.0).normalize().multiplyScalar(radius * 6.5)));
    tc.lookAt(centre);
    const l = new THREE.DirectionalLight(0xffffff, 2.0);
    tc.add(l);
    ts.add(tc);
    ts.add(on);
    ts.add(handMesh(c, 0.8));
    thumbR.render(ts, tc);
    const out = el('canvas', { width: 170, height: 170 });
    out.getContext('2d').drawImage(thumbR.domElement, 0, 0);
    const m = meta[j] || {};
    row.append(el('div', { class: 'thumb' + (j === 0 ? ' chosen' : '') }, out,
      `#${j + 1} q ${fmt(m.quality, 4)}`, el('br'), `ε ${fmt(m.stability_epsilon, 4)}`));
  });
});

// ---- manipulation: what the hand did, in order ---------------------------------------------
// Every pick-up attempt with its outcome, each grasp's views and the slips found in them, how
// its views ended (a drop noticed), the object found again on the table after each put-down
// (the registration's residual), and the re-grasp attempts that failed.
const man = el('section', { id: 'manipulation' }, el('h2', {}, 'Manipulation'));
main.append(man);
const colours = { picked: '#1e8449', dropped: '#c0392b', slid: '#e67e22', no_contact: '#7f8c8d',
                  empty_hand: '#7f8c8d', refused: '#7f8c8d' };
const events = el('table', { id: 'timeline' });
events.append(el('tr', {}, ...['#', 'grasp', 'event', 'details'].map((h) => el('th', {}, h))));
let step = 0;
function event(grasp, what, details, colour, cls) {
  const badge = el('span', { class: 'event ' + cls, style: `background:${colour}` }, what);
  events.append(el('tr', {}, el('td', {}, ++step), el('td', {}, grasp), el('td', {}, badge), el('td', {}, details)));
}
function attempts(list, grasp) {
  (list || []).forEach((a, k) => event(grasp, `pick-up ${k + 1}: ${a.outcome}`,
    (a.at_s != null ? `at ${fmt(a.at_s, 1)} s: ` : '') +
    `candidate #${a.rank + 1}, ${a.kind || 'grasp'}, ε ${fmt(a.epsilon, 3)}` +
    (a.shift_in_hand_mm != null ? `, in the hand ${fmt(a.shift_in_hand_mm, 1)} mm from the plan` : '') +
    (a.evidence ? `; ${a.evidence}` : ''),
    colours[a.outcome] || '#7f8c8d', 'attempt'));
}
const residuals = S.refound_on_table_residual_mm || [];
S.grasps.forEach((g, gi) => {
  attempts(g.pick_up_attempts, gi + 1);
  event(gi + 1, `${g.views} view${g.views === 1 ? '' : 's'}`, (g.views_ended_at_s != null ? `ended at ${fmt(g.views_ended_at_s, 1)} s: ` : 'ended: ') +
        g.termination, '#2471a3', 'views');
  // Slips number grasps and views from 0.
  slips.filter((e) => e.grasp === gi).forEach((e) => event(gi + 1, 'slip found',
    `in view ${e.view + 1}: ${fmt(e.moved_mm, 1)} mm, ${fmt(e.turned_deg, 1)}°; ${e.frames_not_fused} frames not fused` +
    (e.settled ? '' : ' (still moving when the views ended)'), '#e67e22', 'slip'));
  if (g.termination === 'object_lost')
    event(gi + 1, 'object lost from the hand', 'frames showed the hand empty; it was looked for on the table', '#000', 'drop');
  if (gi < residuals.length)
    event(gi + 1, 'found on the table', `registration residual ${fmt(residuals[gi], 2)} mm`, '#117a65', 'refound');
});
attempts(S.failed_regrasp_attempts, 'none made');
const notFound = S.termination === 'object_lost' && residuals.length < S.grasps.length &&
                 !(S.grasps.length && S.grasps[S.grasps.length - 1].termination === 'object_lost');
event('–', `scan ended: ${S.termination}`,
      notFound ? 'the object was not found on the table after the put-down' : '', '#555', 'end');
man.append(events);

// ---- figures and options --------------------------------------------------------------------
const fig = el('section', {}, el('h2', {}, 'Summary'));
main.append(fig);
const t = el('table');
const rows = [
  ['termination', S.termination], ['views', S.views.length], ['grasps', S.grasps.length],
  ['coverage (τ = 3 mm)', S.coverage !== undefined ? (100 * S.coverage).toFixed(1) + ' %' : '–'],
  ['accuracy mean / RMS / p95, mm', S.accuracy_mm ? `${fmt(S.accuracy_mm.mean, 2)} / ${fmt(S.accuracy_mm.rms, 2)} / ${fmt(S.accuracy_mm.p95, 2)}` : '–'],
  ['observed fraction of the model', fmt(S.observed_fraction, 3)], ['mean entropy, nats', fmt(S.mean_entropy, 3)],
  ['view evaluations', `${S.view_evaluations} (${fmt(S.view_evaluations_per_s, 0)} /s)`],
  ['frames fused', S.frames], ['trajectory time, s', fmt(S.trajectory_s, 1)],
  ...Object.entries(S.timing_s || {}).map(([k, v]) => [`time: ${k}, s`, fmt(v, 2)]),
];
if (S.fscore) for (const [k, v] of Object.entries(S.fscore)) rows.push([`F-score at ${k}`, fmt(v.f, 3)]);
for (const [k, v] of rows) t.append(el('tr', {}, el('td', {}, k), el('td', {}, v)));
fig.append(t);
fig.append(el('h2', { style: 'margin-top:12px' }, 'Options the scan ran with'));
fig.append(el('pre', {}, JSON.stringify(S.options, null, 2)));

state.views = S.views.length;
state.ready = true;
// #only-ID shows just that section under the header (for screenshots of one part).
if (location.hash.startsWith('#only-')) {
  for (const sec of document.querySelectorAll('main > section'))
    if (sec.id !== location.hash.slice(6).replace(/-glb$/, '')) sec.style.display = 'none';
}
// The textured model (model.glb, which scans with colour write), read by three.js's glTF loader:
// one more entry under 'Show'. #glb (or #only-model-glb) shows it first.
async function texturedModel() {
  if (!D.model_glb) return null;
  const loader = new GLTFLoader();
  // Images through an <img> element (three's TextureLoader) rather than createImageBitmap: a
  // headless browser waits for those, and they decode this atlas several times faster there.
  loader.register((parser) => {
    parser.textureLoader = new THREE.TextureLoader(parser.options.manager);
    return { name: 'inhand_image_element' };
  });
  const gltf = await loader.parseAsync(decode(D.model_glb, Uint8Array).buffer, '');
  const group = new THREE.Group();
  group.rotation.x = Math.PI / 2;  // glTF is y-up; the scan's frame (and this viewer) z-up
  group.add(gltf.scene);
  let triangles = 0, textured = false;
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    triangles += o.geometry.attributes.position.count / 3;
    textured = textured || !!(o.material.map && o.material.map.image);
  });
  return { group, triangles, textured };
}
let glbTest = null;
try {
  const glb = await texturedModel();
  if (glb) {
    const before = current;
    models.push({ label: 'textured model (model.glb)', mesh: glb.group, hand: null });
    select.append(el('option', { value: models.length - 1 }, 'textured model (model.glb)'));
    show(models[models.length - 1]);
    glbTest = { triangles: glb.triangles, textured: glb.textured, nonBackground: state.nonBackgroundFraction() };
    if (location.hash.includes('glb')) select.value = models.length - 1; else show(before);
  }
} catch (e) {
  glbTest = { error: String(e) };
}
window.inhandSelfTest({ nonBackground: state.nonBackgroundFraction(), charts: state.charts, views: state.views,
                        thumbnails: document.querySelectorAll('.thumb canvas').length, glb: glbTest,
                        attempts: document.querySelectorAll('#timeline .event.attempt').length,
                        slips: document.querySelectorAll('#timeline .event.slip').length });
