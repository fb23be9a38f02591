// The 3-D view: a three.js renderer with OrbitControls that draws on demand (no animation loop),
// layer toggles, reset and top view, and picking of plane meshes.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

export class Viewer {
  constructor(container, state) {
    this.container = container;
    this.state = state;
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xfbfcfd);
    this.layers = new Map();
    this.pickables = [];
    this.up = new THREE.Vector3(0, 0, 1);
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    container.appendChild(this.renderer.domElement);
    this.camera = new THREE.PerspectiveCamera(50, 1, 0.01, 1e5);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.screenSpacePanning = true;
    this.controls.addEventListener('change', () => this.requestRender());
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8a9099, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.2);
    sun.position.set(1, 2, 3);
    this.scene.add(sun);
    this.sun = sun;
    this.renderPending = false;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  requestRender() {
    if (this.renderPending) return;
    this.renderPending = true;
    requestAnimationFrame(() => {
      this.renderPending = false;
      this.renderer.render(this.scene, this.camera);
      if (this.state.firstFrameMs === null) {
        this.state.firstFrameMs = performance.now();
        this.state.ready = true;
      }
    });
  }

  /// Adds `object` as the layer `name` (label, swatch colour) with a visibility checkbox.
  addLayer(name, label, object, visible, colour) {
    object.name = name;
    object.visible = visible;
    this.scene.add(object);
    this.layers.set(name, object);
    const toolbar = this.container.querySelector('#toolbar');
    const item = document.createElement('label');
    const box = document.createElement('input');
    box.type = 'checkbox';
    box.checked = visible;
    box.dataset.layer = name;
    box.addEventListener('change', () => { object.visible = box.checked; this.requestRender(); });
    item.appendChild(box);
    if (colour) {
      const sw = document.createElement('span');
      sw.className = 'swatch';
      sw.style.background = colour;
      item.appendChild(sw);
    }
    item.appendChild(document.createTextNode(label));
    toolbar.appendChild(item);
  }

  /// A selector of the up axis (auto = `auto`, or a world axis); calls onChange after setting it.
  addUpSelector(auto, onChange) {
    const choices = [['auto', auto], ['+z', [0, 0, 1]], ['-z', [0, 0, -1]], ['+y', [0, 1, 0]],
      ['-y', [0, -1, 0]], ['+x', [1, 0, 0]], ['-x', [-1, 0, 0]]];
    const label = document.createElement('label');
    label.textContent = 'Up ';
    const select = document.createElement('select');
    select.id = 'up-axis';
    for (const [name] of choices) select.add(new Option(name, name));
    select.addEventListener('change', () => {
      this.up.copy(new THREE.Vector3(...choices.find((c) => c[0] === select.value)[1]).normalize());
      onChange();
    });
    label.appendChild(select);
    this.container.querySelector('#toolbar').appendChild(label);
  }

  addButton(label, id, onClick) {
    const b = document.createElement('button');
    b.textContent = label;
    b.id = id;
    b.addEventListener('click', onClick);
    this.container.querySelector('#toolbar').appendChild(b);
    return b;
  }

  /// Frames the box of the visible content from an oblique view above it (along `this.up`).
  frame(box, top = false) {
    const centre = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 0.5);
    const dist = radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 0.8;
    const up = this.up.clone();
    const side = Math.abs(up.z) < 0.9 ? new THREE.Vector3(0, 0, 1) : new THREE.Vector3(1, 0, 0);
    const horiz = side.clone().sub(up.clone().multiplyScalar(side.dot(up))).normalize();
    const right = new THREE.Vector3().crossVectors(horiz, up).normalize();
    let dir;
    if (top) {
      dir = up.clone();
      this.camera.up.copy(horiz);
    } else {
      dir = up.clone().multiplyScalar(0.8).add(horiz.clone().multiplyScalar(-0.75)).add(right.multiplyScalar(-0.45)).normalize();
      this.camera.up.copy(up);
    }
    this.camera.position.copy(centre).add(dir.multiplyScalar(dist));
    this.camera.near = dist / 1000;
    this.camera.far = dist * 100;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
    this.sun.position.copy(up).multiplyScalar(3).add(horiz).add(right);
    this.requestRender();
  }

  /// Calls onHover(object|null) while the pointer moves over pickable meshes, onPick on click.
  enablePicking(onHover, onPick) {
    const ray = new THREE.Raycaster();
    const ndc = new THREE.Vector2();
    const el = this.renderer.domElement;
    const pick = (ev) => {
      const r = el.getBoundingClientRect();
      ndc.set(((ev.clientX - r.left) / r.width) * 2 - 1, -((ev.clientY - r.top) / r.height) * 2 + 1);
      ray.setFromCamera(ndc, this.camera);
      const visible = this.pickables.filter((o) => o.visible && o.parent && o.parent.visible);
      const hit = ray.intersectObjects(visible, false)[0];
      return hit ? hit.object : null;
    };
    let down = null;
    el.addEventListener('pointermove', (ev) => { if (ev.buttons === 0) onHover(pick(ev)); });
    el.addEventListener('pointerdown', (ev) => { down = [ev.clientX, ev.clientY]; });
    el.addEventListener('pointerup', (ev) => {
      if (down && Math.hypot(ev.clientX - down[0], ev.clientY - down[1]) < 4) onPick(pick(ev));
      down = null;
    });
  }
}

/// The box holding all but the outer 2 % of `points` (flat xyz) on each axis, grown by a tenth:
/// one far stray plane or point does not shrink the view of the rest to a dot.
export function robustBox(points) {
  const n = points.length / 3;
  const box = new THREE.Box3();
  if (n === 0) return box;
  const lo = [], hi = [];
  for (let a = 0; a < 3; ++a) {
    const v = new Float32Array(n);
    for (let i = 0; i < n; ++i) v[i] = points[3 * i + a];
    v.sort();
    lo.push(v[Math.floor(0.02 * (n - 1))]);
    hi.push(v[Math.ceil(0.98 * (n - 1))]);
  }
  box.set(new THREE.Vector3(...lo), new THREE.Vector3(...hi));
  return box.expandByVector(box.getSize(new THREE.Vector3()).multiplyScalar(0.1));
}

/// Decodes base64 into a typed array of `Type`.
export function decodeBase64(text, Type) {
  const bin = atob(text);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; ++i) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer, 0, Math.floor(bytes.length / Type.BYTES_PER_ELEMENT));
}

/// Positions of points packed by the report writer (16-bit quantised over their box).
export function unpackPoints(packed) {
  const q = decodeBase64(packed.xyz, Uint16Array);
  const out = new Float32Array(q.length);
  for (let i = 0; i < q.length; i += 3) {
    for (let a = 0; a < 3; ++a) out[i + a] = packed.min[a] + q[i + a] * packed.step[a];
  }
  return out;
}

/// A Points object from a flat position array and a flat 0..1 colour array.
export function makePoints(positions, colours, size = 2) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  g.setAttribute('color', new THREE.BufferAttribute(colours, 3));
  return new THREE.Points(g, new THREE.PointsMaterial({ size, sizeAttenuation: false, vertexColors: true }));
}

/// A polyline through `points` ([[x, y, z], ...]).
export function makeLine(points, colour, width = 1) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(points.flat()), 3));
  return new THREE.Line(g, new THREE.LineBasicMaterial({ color: colour, linewidth: width }));
}

/// A colour map from blue through green to red for t in [0, 1] (for heights).
export function ramp(t) {
  t = Math.min(1, Math.max(0, t));
  const c = new THREE.Color();
  c.setHSL((1 - t) * 0.66, 0.75, 0.5);
  return c;
}

export { THREE };
