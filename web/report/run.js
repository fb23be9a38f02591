// The page of a `planeslam run` output folder.
import { Viewer, THREE, unpackPoints, makePoints, makeLine, ramp, robustBox } from './viewer.js';
import { statGrid, fmt, planeInfoTable, showNotes, showConfig } from './summary.js';
import { framePlots, stageTimePlot, inlineSvg } from './plots.js';

function basisOf(n) {
  const a = Math.abs(n.x) < 0.9 ? new THREE.Vector3(1, 0, 0) : new THREE.Vector3(0, 1, 0);
  const u = new THREE.Vector3().crossVectors(n, a).normalize();
  const v = new THREE.Vector3().crossVectors(n, u).normalize();
  return [u, v];
}

/// One mesh per plane: each outline part triangulated in the plane's own 2-D coordinates.
function planeMesh(plane) {
  const n = new THREE.Vector3(...plane.normal).normalize();
  const [u, v] = basisOf(n);
  const positions = [];
  for (const polygon of plane.polygons) {
    if (polygon.length < 3) continue;
    const pts3 = polygon.map((p) => new THREE.Vector3(...p));
    const pts2 = pts3.map((p) => new THREE.Vector2(p.dot(u), p.dot(v)));
    for (const [a, b, c] of THREE.ShapeUtils.triangulateShape(pts2, [])) {
      for (const i of [a, b, c]) positions.push(pts3[i].x, pts3[i].y, pts3[i].z);
    }
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
  g.computeVertexNormals();
  const colour = new THREE.Color(...plane.color.map((c) => c / 255));
  const m = new THREE.MeshLambertMaterial({
    color: colour, side: THREE.DoubleSide, transparent: true, opacity: 0.82,
    polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
  });
  const mesh = new THREE.Mesh(g, m);
  mesh.userData.plane = plane;
  mesh.userData.colour = colour;
  return mesh;
}

/// Every plane's outline edges as one LineSegments object, each in a darker shade of its plane.
function outlines(planes) {
  const pos = [], col = [];
  for (const plane of planes) {
    const c = plane.color.map((v) => v / 400);
    for (const polygon of plane.polygons) {
      for (let i = 0; i < polygon.length; ++i) {
        pos.push(...polygon[i], ...polygon[(i + 1) % polygon.length]);
        col.push(...c, ...c);
      }
    }
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
  g.setAttribute('color', new THREE.Float32BufferAttribute(col, 3));
  return new THREE.LineSegments(g, new THREE.LineBasicMaterial({ vertexColors: true }));
}

/// The planes' outlines from the packed vertex block ("parts": vertices per outline part).
function unpackPolygons(data) {
  const pts = data.polygon_points ? unpackPoints(data.polygon_points) : new Float32Array(0);
  let at = 0;
  for (const plane of data.planes) {
    plane.polygons = (plane.parts || []).map((n) => {
      const polygon = [];
      for (let i = 0; i < n; ++i, at += 3) polygon.push([pts[at], pts[at + 1], pts[at + 2]]);
      return polygon;
    });
  }
}

/// The world's up direction: the sensor's up axis averaged over the keyframes (a camera's -y, a
/// scanner's +z: the one that stays put while the sensor turns), or world +z with ground truth
/// (ground-truth frames are gravity-aligned, z up) or when the two cannot be told apart; snapped to
/// a world axis within 20 degrees.
function upDirection(data) {
  if (data.ground_truth && data.ground_truth.length) return new THREE.Vector3(0, 0, 1);
  const cam = new THREE.Vector3(), lidar = new THREE.Vector3();
  for (const k of data.keyframes) {
    const q = new THREE.Quaternion(k[3], k[4], k[5], k[6]);
    cam.add(new THREE.Vector3(0, -1, 0).applyQuaternion(q));
    lidar.add(new THREE.Vector3(0, 0, 1).applyQuaternion(q));
  }
  const count = Math.max(1, data.keyframes.length);
  const up = cam.length() / count > lidar.length() / count + 0.1 ? cam : lidar;
  if (up.lengthSq() < 1e-9) return new THREE.Vector3(0, 0, 1);
  up.normalize();
  for (const axis of [[1, 0, 0], [0, 1, 0], [0, 0, 1]]) {
    const a = new THREE.Vector3(...axis);
    const c = up.dot(a);
    if (Math.abs(c) > Math.cos(THREE.MathUtils.degToRad(20))) return a.multiplyScalar(Math.sign(c));
  }
  return up;
}

function summaryStats(data) {
  const s = data.summary, m = data.metrics || {};
  const withPolygon = data.planes.filter((p) => p.polygons && p.polygons.length > 0).length;
  const stats = [
    { label: 'Frames', key: 'summary.frames', value: s.frames },
    { label: 'Keyframes', key: 'summary.keyframes', value: s.keyframes },
    { label: 'Loop closures', key: 'summary.loop_closures', value: s.loop_closures },
    { label: 'Map planes', key: 'summary.map_planes', value: s.map_planes },
    { label: 'Planes in plane_map.json', key: 'plane_map.planes', value: data.planes.length },
    { label: 'Planes with an outline', key: 'plane_map.with_polygon', value: withPolygon },
    { label: 'Speed', key: 'summary.frames_per_second', value: s.frames_per_second, digits: 1, unit: 'frames/s' },
    { label: 'Degenerate frames', key: 'summary.degenerate_frames', value: s.degenerate_frames },
    { label: 'Untracked frames', key: 'summary.untracked_frames', value: s.untracked_frames },
    { label: 'Skipped frames', key: 'summary.skipped_frames', value: s.skipped_frames },
  ];
  if (m.ate) {
    stats.push({ label: 'ATE rmse (SE(3) aligned)', key: 'metrics.ate.rmse', value: m.ate.rmse, scale: 100, digits: 3, unit: 'cm' });
    stats.push({ label: 'ATE max', key: 'metrics.ate.max', value: m.ate.max, scale: 100, digits: 3, unit: 'cm' });
  }
  if (m.rpe_translation_m_per_frame) {
    stats.push({ label: 'RPE translation rmse', key: 'metrics.rpe_translation_m_per_frame.rmse', value: m.rpe_translation_m_per_frame.rmse, scale: 1000, digits: 3, unit: 'mm/frame' });
  }
  if (m.rpe_rotation_deg_per_frame) {
    stats.push({ label: 'RPE rotation rmse', key: 'metrics.rpe_rotation_deg_per_frame.rmse', value: m.rpe_rotation_deg_per_frame.rmse, digits: 4, unit: 'deg/frame' });
  }
  return stats;
}

export function runPage(data, state) {
  unpackPolygons(data);
  const s = data.summary;
  document.getElementById('view-title').textContent =
    '3-D view: plane map, keyframes' + (data.ground_truth ? ', ground truth' : '') + ', loop closures';
  statGrid(document.getElementById('summary'), [{ label: 'Sequence', key: 'summary.input', value: s.input, text: true }, ...summaryStats(data)]);
  const notes = [...(data.notes || [])];
  if (s.interrupted) notes.push('The run was interrupted: the outputs cover the frames processed.');
  if (s.stopped_at_bad_frame) notes.push('The run stopped at a bad frame.');
  for (const b of s.bad_frames || []) notes.push(`Frame ${b.index} skipped: ${b.error}`);
  showNotes(notes);
  showConfig(data.config_yaml);
  buildRunScene(data, state);
  const plots = document.getElementById('plots');
  for (const [name, title] of [['trajectories.svg', 'Trajectories, top view, coloured by ATE'], ['ate_over_time.svg', 'ATE over time']]) {
    if (data.svgs && data.svgs[name]) inlineSvg(plots, title, data.svgs[name]);
  }
  if (data.frames_csv) framePlots(plots, data.frames_csv);
  if (s.time_ms) stageTimePlot(plots, s.time_ms, s.frames);
  document.getElementById('plots-section').hidden = plots.childElementCount === 0;
}

function buildRunScene(data, state) {
  const viewer = new Viewer(document.getElementById('view'), state);
  viewer.up = upDirection(data);
  const autoUp = viewer.up.toArray();
  const extent = [];  // what the view frames: outline vertices, keyframes (or else the cloud)

  const planes = new THREE.Group();
  for (const plane of data.planes) {
    if (!plane.polygons || plane.polygons.length === 0) continue;
    const mesh = planeMesh(plane);
    planes.add(mesh);
    viewer.pickables.push(mesh);
    for (const polygon of plane.polygons) for (const p of polygon) extent.push(...p);
  }
  viewer.addLayer('planes', `Planes (${planes.children.length})`, planes, true);
  viewer.addLayer('outlines', 'Outlines', outlines(data.planes), true);

  const kfPoints = data.keyframes.map((k) => [k[0], k[1], k[2]]);
  const trajectory = new THREE.Group();
  const line = makeLine(kfPoints, 0xe0660f);
  line.name = 'keyframe-line';
  trajectory.add(line);
  const kfColours = new Float32Array(kfPoints.length * 3);
  const orange = new THREE.Color(0xe0660f);
  for (let i = 0; i < kfPoints.length; ++i) orange.toArray(kfColours, 3 * i);
  trajectory.add(makePoints(new Float32Array(kfPoints.flat()), kfColours, 5));
  for (const p of kfPoints) extent.push(...p);
  viewer.addLayer('keyframes', `Keyframes (${kfPoints.length})`, trajectory, true, '#e0660f');

  let gtCount = 0;
  if (data.ground_truth && data.ground_truth.length > 1) {
    gtCount = data.ground_truth.length;
    viewer.addLayer('ground_truth', 'Ground truth', makeLine(data.ground_truth, 0x1a9a3a), true, '#1a9a3a');
  }

  const loopPositions = [];
  for (const [a, b] of data.loops) loopPositions.push(...kfPoints[a], ...kfPoints[b]);
  const lg = new THREE.BufferGeometry();
  lg.setAttribute('position', new THREE.Float32BufferAttribute(loopPositions, 3));
  viewer.addLayer('loops', `Loop closures (${data.loops.length})`,
    new THREE.LineSegments(lg, new THREE.LineBasicMaterial({ color: 0xc0158f })), true, '#c0158f');

  let cloudCount = 0;
  if (data.cloud && data.cloud.count > 0) {
    const pos = unpackPoints(data.cloud);
    cloudCount = pos.length / 3;
    // Coloured by height along the up axis, the ramp spanning the 2nd to 98th percentile.
    const up = viewer.up;
    const heights = new Float32Array(cloudCount);
    for (let i = 0; i < cloudCount; ++i) heights[i] = pos[3 * i] * up.x + pos[3 * i + 1] * up.y + pos[3 * i + 2] * up.z;
    const sorted = heights.slice().sort();
    const lo = sorted[Math.floor(0.02 * (cloudCount - 1))], hi = sorted[Math.ceil(0.98 * (cloudCount - 1))];
    const col = new Float32Array(pos.length);
    for (let i = 0; i < cloudCount; ++i) ramp((heights[i] - lo) / Math.max(hi - lo, 1e-6)).toArray(col, 3 * i);
    viewer.addLayer('cloud', `Keyframe points (${cloudCount})`, makePoints(pos, col, 1.5), planes.children.length === 0);
    if (planes.children.length === 0) for (const v of pos) extent.push(v);
  }
  const box = robustBox(extent);
  if (box.isEmpty()) box.expandByPoint(new THREE.Vector3()).expandByScalar(1);
  viewer.addUpSelector(autoUp, () => viewer.frame(box));

  viewer.addButton('Reset view', 'reset-view', () => viewer.frame(box));
  viewer.addButton('Top view', 'top-view', () => viewer.frame(box, true));
  const info = document.getElementById('info');
  let pinned = null, hovered = null;
  const highlight = (mesh, on) => {
    if (!mesh) return;
    mesh.material.emissive.set(on ? 0x333333 : 0x000000);
    mesh.material.opacity = on ? 1.0 : 0.82;
  };
  const show = (mesh) => {
    if (!mesh) { info.hidden = true; return; }
    info.hidden = false;
    info.innerHTML = planeInfoTable(mesh.userData.plane);
  };
  viewer.enablePicking((mesh) => {
    if (mesh === hovered) return;
    if (hovered !== pinned) highlight(hovered, false);
    hovered = mesh;
    highlight(hovered, true);
    show(hovered || pinned);
    viewer.requestRender();
  }, (mesh) => {
    highlight(pinned, false);
    pinned = mesh;
    highlight(pinned, true);
    show(pinned);
    viewer.requestRender();
  });
  viewer.frame(box);

  state.viewer = viewer;
  state.counts = {
    planeMeshes: planes.children.length,
    trajectoryVertices: line.geometry.getAttribute('position').count,
    loopEdges: lg.getAttribute('position').count / 2,
    groundTruthVertices: gtCount,
    cloudPoints: cloudCount,
  };
}
