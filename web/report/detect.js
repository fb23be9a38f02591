// The page of a `planeslam detect` result: depth and labelled images, the plane table and the
// segmented points in 3-D coloured by plane.
import { Viewer, THREE, decodeBase64, unpackPoints, makePoints } from './viewer.js';
import { statGrid, showConfig } from './summary.js';

function drawImages(data) {
  const img = data.image;
  const grey = decodeBase64(img.grey, Uint8Array);
  const labels = decodeBase64(img.labels, Uint16Array);
  const colours = data.colours;
  const make = (caption, pixel) => {
    const fig = document.createElement('figure');
    const canvas = document.createElement('canvas');
    canvas.width = img.width;
    canvas.height = img.height;
    const ctx = canvas.getContext('2d');
    const out = ctx.createImageData(img.width, img.height);
    for (let i = 0; i < grey.length; ++i) {
      const [r, g, b] = pixel(i);
      out.data.set([r, g, b, 255], 4 * i);
    }
    ctx.putImageData(out, 0, 0);
    const cap = document.createElement('figcaption');
    cap.textContent = caption;
    fig.append(canvas, cap);
    document.getElementById('images').appendChild(fig);
    return canvas;
  };
  make('Range (near = light, invalid = black)', (i) => [grey[i], grey[i], grey[i]]);
  make('Planes (colour = plane id, as labels_color.png)', (i) => {
    const c = labels[i] > 0 ? colours[labels[i]] : null;
    if (!c) return [grey[i], grey[i], grey[i]];
    return c.map((v) => (3 * v + grey[i]) >> 2);
  });
  document.getElementById('images-section').hidden = false;
}

function planeTable(data) {
  const planes = data.detect.planes;
  const rows = planes.map((p) => {
    const c = data.colours[p.id] || [200, 200, 200];
    return `<tr data-plane="${p.id}"><td class="sw"><span style="background:rgb(${c.join(',')})"></span></td><td>${p.id}</td>` +
      `<td>${p.normal.map((x) => x.toFixed(3)).join(', ')}</td><td>${p.d.toFixed(3)}</td><td>${p.points}</td>` +
      `<td>${(1000 * p.rms).toFixed(1)}</td><td>${p.centroid.map((x) => x.toFixed(2)).join(', ')}</td></tr>`;
  });
  document.getElementById('table').innerHTML = '<table class="planes"><thead><tr><th></th><th>id</th><th>normal (sensor frame)</th>' +
    '<th>d [m]</th><th>points</th><th>rms [mm]</th><th>centroid [m]</th></tr></thead><tbody>' + rows.join('') + '</tbody></table>';
  document.getElementById('table-title').textContent = `Planes (${planes.length})`;
  document.getElementById('table-section').hidden = false;
}

export function detectPage(data, state) {
  const d = data.detect;
  document.getElementById('view-title').textContent = '3-D view: segmented points, coloured by plane (sensor frame)';
  document.querySelector('.hint').textContent = 'Drag: orbit. Right-drag or shift-drag: pan. Wheel: zoom.';
  statGrid(document.getElementById('summary'), [
    { label: 'Input', key: 'detect.input', value: d.input, text: true },
    { label: 'Method', key: 'detect.method', value: d.method, text: true },
    { label: 'Planes', key: 'detect.planes', value: d.planes.length },
    { label: 'Width', key: 'detect.width', value: d.width },
    { label: 'Height', key: 'detect.height', value: d.height },
    { label: 'Valid pixels', key: 'detect.valid_pixels', value: d.valid_pixels },
    { label: 'Assigned pixels', key: 'detect.assigned_pixels', value: d.assigned_pixels },
    { label: 'Detection time', key: 'detect.detect_ms', value: d.detect_ms, digits: 2, unit: 'ms' },
  ]);
  showConfig(data.config_yaml);
  drawImages(data);
  planeTable(data);

  const viewer = new Viewer(document.getElementById('view'), state);
  const pos = unpackPoints(data.cloud);
  const labels = decodeBase64(data.cloud.labels, Uint16Array);
  const col = new Float32Array(pos.length);
  let forward = 0;
  for (let i = 0; i < labels.length; ++i) {
    const c = labels[i] > 0 ? data.colours[labels[i]] : null;
    const rgb = c ? c.map((v) => v / 255) : [0.62, 0.62, 0.62];
    col.set(rgb, 3 * i);
    if (pos[3 * i + 2] > 0) ++forward;
  }
  const planeIds = new Set(Array.from(labels).filter((l) => l > 0));
  viewer.addLayer('points', `Points (${labels.length})`, makePoints(pos, col, 2), true);
  // A depth camera sees along +z with y down; a scanner sees all round, z up.
  const camera = forward > 0.9 * labels.length;
  viewer.up = camera ? new THREE.Vector3(0, -1, 0) : new THREE.Vector3(0, 0, 1);
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  g.computeBoundingBox();
  const box = g.boundingBox.isEmpty() ? new THREE.Box3(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1)) : g.boundingBox;
  const home = () => {
    if (!camera) { viewer.frame(box); return; }
    // From just behind the sensor, looking along its axis, as the images show the scene.
    const c = box.getCenter(new THREE.Vector3());
    viewer.camera.up.set(0, -1, 0);
    viewer.camera.position.set(0, 0, -0.3 * Math.max(0.5, c.z));
    viewer.camera.near = 0.01;
    viewer.camera.far = 1e4;
    viewer.camera.updateProjectionMatrix();
    viewer.controls.target.copy(c);
    viewer.controls.update();
    viewer.requestRender();
  };
  viewer.addButton('Reset view', 'reset-view', home);
  viewer.addButton('Top view', 'top-view', () => viewer.frame(box, true));
  home();
  state.viewer = viewer;
  state.counts = { points: labels.length, planesInCloud: planeIds.size, tableRows: d.planes.length };
}
