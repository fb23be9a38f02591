// Loads report.html files from disk in headless Chromium (Debian's chromium driven by
// playwright-core from web/node_modules) and checks them against the files beside them:
//   node report_browser_test.mjs --run DIR [--detect DIR] [--shots DIR] [--max-first-frame-ms MS]
// Fails on any console error, page error, failed request or request leaving the file; checks one
// mesh per plane with an outline in plane_map.json, one trajectory vertex per keyframe, one loop
// edge per loop closure, the summary figures shown against summary.json / metrics.json /
// plane_map.json (detect: planes.json), and that the 3-D canvas is not blank (pixel variance).
// Exit codes: 0 pass, 1 fail, 77 skipped (no chromium or playwright-core), as ctest's SKIP code.
import { createRequire } from 'node:module';
import { existsSync, readFileSync, mkdirSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const webDir = resolve(here, '..', '..', 'web');
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const chromium = process.env.PLANESLAM_CHROMIUM || '/usr/bin/chromium';
if (!existsSync(chromium)) {
  console.log(`SKIP: ${chromium} not found (Debian package chromium; 'make deps' installs it)`);
  process.exit(77);
}
let playwright;
try {
  playwright = createRequire(join(webDir, 'package.json'))('playwright-core');
} catch (e) {
  console.log("SKIP: playwright-core not in web/node_modules (run 'npm ci --prefix web')");
  process.exit(77);
}

// The variance of the 3-D canvas' grey levels must exceed this (a blank canvas: 0; a rendered
// scene: several hundred).
const MIN_CANVAS_VARIANCE = 20;
const failures = [];
const check = (ok, what) => { if (!ok) failures.push(what); };
const readJson = (path) => JSON.parse(readFileSync(path, 'utf8'));

async function openReport(browser, dir) {
  const file = resolve(dir, 'report.html');
  const url = pathToFileURL(file).href;
  const page = await browser.newPage({ viewport: { width: 1280, height: 1400 } });
  const problems = [];
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console error: ${m.text()}`); });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('requestfailed', (r) => problems.push(`failed request: ${r.url()}`));
  page.on('request', (r) => {
    if (r.url() !== url && !r.url().startsWith('data:')) problems.push(`request outside the file: ${r.url()}`);
  });
  await page.goto(url, { waitUntil: 'load' });
  await page.waitForFunction(() => window.planeslamReport && window.planeslamReport.ready, null, { timeout: 60000 });
  const state = await page.evaluate(() => ({ ...window.planeslamReport, viewer: undefined }));
  check(state.error === null, `${file}: page reports an error: ${state.error}`);
  return { page, problems, state, file };
}

/// Variance of the grey levels of the 3-D canvas (read back from the WebGL drawing buffer).
async function canvasVariance(page) {
  return page.evaluate(() => {
    const gl = document.querySelector('#view canvas');
    const c = document.createElement('canvas');
    c.width = gl.width; c.height = gl.height;
    const ctx = c.getContext('2d');
    ctx.drawImage(gl, 0, 0);
    const px = ctx.getImageData(0, 0, c.width, c.height).data;
    let s = 0, s2 = 0, n = 0;
    for (let i = 0; i < px.length; i += 4 * 7) {
      const g = 0.299 * px[i] + 0.587 * px[i + 1] + 0.114 * px[i + 2];
      s += g; s2 += g * g; ++n;
    }
    return s2 / n - (s / n) ** 2;
  });
}

/// Every [data-key] figure shown: its exact value equals `lookup(key)` and its text shows it.
async function checkFigures(page, file, lookup) {
  const shown = await page.$$eval('[data-key]', (els) => els.map((e) => ({ key: e.dataset.key, value: JSON.parse(e.dataset.value), scale: +e.dataset.scale, text: e.textContent })));
  check(shown.length > 0, `${file}: no summary figures`);
  for (const f of shown) {
    const expected = lookup(f.key);
    check(expected !== undefined, `${file}: figure ${f.key} has no source`);
    check(JSON.stringify(expected) === JSON.stringify(f.value), `${file}: ${f.key} shows ${JSON.stringify(f.value)}, the file has ${JSON.stringify(expected)}`);
    if (typeof expected === 'number') {
      const text = parseFloat(f.text);
      const decimals = (f.text.split('.')[1] || '').length;
      check(Math.abs(text - expected * f.scale) <= 0.5 * 10 ** -decimals * 1.0001 + 1e-9 || Math.abs(text / (expected * f.scale) - 1) < 1e-3,
        `${file}: ${f.key} text '${f.text}' does not show ${expected * f.scale}`);
    } else {
      check(f.text === String(expected), `${file}: ${f.key} text '${f.text}' != '${expected}'`);
    }
  }
  return shown.length;
}

async function shoot(page, name) {
  if (!args.shots) return;
  mkdirSync(args.shots, { recursive: true });
  await page.locator('#view').screenshot({ path: join(args.shots, `${name}_view.png`) });
  await page.screenshot({ path: join(args.shots, `${name}_page.png`), fullPage: true });
}

async function testRun(browser, dir) {
  const { page, problems, state, file } = await openReport(browser, dir);
  const summary = readJson(join(dir, 'summary.json'));
  const map = readJson(join(dir, 'plane_map.json'));
  const metrics = existsSync(join(dir, 'metrics.json')) ? readJson(join(dir, 'metrics.json')) : {};
  const withPolygon = map.planes.filter((p) => (p.polygons || []).length > 0).length;
  const c = state.counts;
  check(c.planeMeshes === withPolygon, `${file}: ${c.planeMeshes} plane meshes, plane_map.json has ${withPolygon} planes with an outline`);
  check(c.trajectoryVertices === summary.keyframes, `${file}: trajectory has ${c.trajectoryVertices} vertices, summary.json ${summary.keyframes} keyframes`);
  // The graph keeps the accepted closures; loop_closures also counts those retracted since.
  const kept = summary.closures ? summary.closures.accepted : summary.loop_closures;
  check(c.loopEdges === kept, `${file}: ${c.loopEdges} loop edges, summary.json ${kept} closures kept`);
  if (existsSync(join(dir, 'ground_truth_tum.txt'))) check(c.groundTruthVertices > 1, `${file}: ground truth not drawn`);
  const planes = { planes: map.planes.length, with_polygon: withPolygon };
  const figures = await checkFigures(page, file, (key) => {
    const [root, ...path] = key.split('.');
    const source = { summary, metrics, plane_map: planes }[root];
    return path.reduce((o, k) => (o === undefined || o === null ? undefined : o[k]), source);
  });
  // Click the largest planes (up to 20, until one is picked): the info box must name a plane of
  // plane_map.json, and one click the plane aimed at (others may hit a plane in front of it).
  const targets = await page.evaluate(() => {
    const v = window.planeslamReport.viewer;
    const r = v.renderer.domElement.getBoundingClientRect();
    const meshes = [...v.layers.get('planes').children].sort((a, b) => b.userData.plane.area - a.userData.plane.area);
    // Aim at the centre of each mesh's largest triangle (a point on the plane, not in a hole).
    return meshes.slice(0, 20).map((m) => {
      const p = m.geometry.getAttribute('position');
      const a = m.position.clone(), b = a.clone(), c = a.clone(), best = a.clone();
      let bestArea = -1;
      for (let i = 0; i < p.count; i += 3) {
        a.fromBufferAttribute(p, i); b.fromBufferAttribute(p, i + 1); c.fromBufferAttribute(p, i + 2);
        const area = b.clone().sub(a).cross(c.clone().sub(a)).length();
        if (area > bestArea) { bestArea = area; best.copy(a).add(b).add(c).multiplyScalar(1 / 3); }
      }
      const q = best.project(v.camera);
      return { id: m.userData.plane.id, x: r.left + (q.x + 1) / 2 * r.width, y: r.top + (1 - q.y) / 2 * r.height };
    });
  });
  const ids = new Set(map.planes.map((p) => p.id));
  let hits = 0;
  for (const t of targets) {
    await page.mouse.move(t.x, t.y);
    await page.mouse.click(t.x, t.y);
    const shown = await page.$eval('#info', (e) => (e.hidden ? null : +e.querySelector('b').textContent));
    if (shown !== null) check(ids.has(shown), `${file}: info box shows plane ${shown}, not in plane_map.json`);
    if (shown === t.id && ++hits) break;
  }
  check(targets.length === 0 || hits > 0, `${file}: clicking the largest planes picked none of them`);
  await page.mouse.move(0, 0);
  await shoot(page, args.name || 'run');
  // The point cloud toggle, the top view and the reset.
  if (c.cloudPoints > 0) {
    const box2 = page.locator('input[data-layer="cloud"]');
    if (!(await box2.isChecked())) await box2.check();
  }
  await page.click('#top-view');
  await page.click('#reset-view');
  await page.waitForTimeout(200);
  const variance = await canvasVariance(page);
  check(variance > MIN_CANVAS_VARIANCE, `${file}: 3-D canvas blank (grey variance ${variance.toFixed(1)})`);
  if (args.shots && c.cloudPoints > 0) await page.locator('#view').screenshot({ path: join(args.shots, `${args.name || 'run'}_cloud.png`) });
  const maxFirst = args['max-first-frame-ms'] ? +args['max-first-frame-ms'] : Infinity;
  check(state.firstFrameMs <= maxFirst, `${file}: first frame after ${state.firstFrameMs.toFixed(0)} ms (limit ${maxFirst})`);
  failures.push(...problems.map((p) => `${file}: ${p}`));
  console.log(`run report ${file}: ${c.planeMeshes} plane meshes (${hits ? 'picked by a click' : 'none picked'}), ${c.trajectoryVertices} keyframe vertices, ${c.loopEdges} loop edges, ` +
    `${c.groundTruthVertices} ground-truth vertices, ${c.cloudPoints} cloud points, ${figures} figures checked, canvas variance ${variance.toFixed(0)}, first frame ${state.firstFrameMs.toFixed(0)} ms`);
  await page.close();
}

async function testDetect(browser, dir) {
  const { page, problems, state, file } = await openReport(browser, dir);
  const planes = readJson(join(dir, 'planes.json'));
  const c = state.counts;
  check(c.tableRows === planes.planes.length, `${file}: plane table has ${c.tableRows} rows, planes.json ${planes.planes.length} planes`);
  const rows = await page.$$eval('tr[data-plane]', (r) => r.length);
  check(rows === planes.planes.length, `${file}: ${rows} table rows in the page, planes.json ${planes.planes.length} planes`);
  check(c.points > 0 && c.planesInCloud > 0, `${file}: no segmented points shown`);
  const figures = await checkFigures(page, file, (key) => {
    const k = key.replace(/^detect\./, '');
    return k === 'planes' ? planes.planes.length : planes[k];
  });
  const images = await page.$$eval('#images canvas', (cs) => cs.length);
  check(images === 2, `${file}: ${images} images, expected depth and labels`);
  const variance = await canvasVariance(page);
  check(variance > MIN_CANVAS_VARIANCE, `${file}: 3-D canvas blank (grey variance ${variance.toFixed(1)})`);
  await shoot(page, (args.name || 'detect') + '_detect');
  failures.push(...problems.map((p) => `${file}: ${p}`));
  console.log(`detect report ${file}: ${c.tableRows} planes in the table, ${c.points} points (${c.planesInCloud} planes), ${figures} figures checked, canvas variance ${variance.toFixed(0)}, first frame ${state.firstFrameMs.toFixed(0)} ms`);
  await page.close();
}

const browser = await playwright.chromium.launch({
  executablePath: chromium,
  headless: true,
  // Software WebGL (SwiftShader) where there is no GPU; no background connections on a closed network.
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic',
    '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
});
try {
  if (args.run) await testRun(browser, args.run);
  if (args.detect) await testDetect(browser, args.detect);
} catch (e) {
  failures.push(`exception: ${e.stack || e}`);
} finally {
  await browser.close();
}
if (failures.length) {
  for (const f of failures) console.log(`FAIL: ${f}`);
  process.exit(1);
}
console.log('PASS');
