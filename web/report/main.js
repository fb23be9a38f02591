// Entry point of report.html: reads the embedded data and builds the page of a run or a detect
// result. window.planeslamReport exposes what the browser test checks: ready, firstFrameMs (the
// page's own performance.now() when the 3-D view first rendered), counts and errors.
import { runPage } from './run.js';
import { detectPage } from './detect.js';

const state = { ready: false, firstFrameMs: null, counts: {}, webgl: true, error: null };
window.planeslamReport = state;

function fail(message) {
  state.error = message;
  state.ready = true;
  const box = document.getElementById('view-message');
  box.hidden = false;
  box.textContent = message;
}

try {
  const data = JSON.parse(document.getElementById('planeslam-data').textContent);
  state.kind = data.kind;
  if (data.kind === 'run') runPage(data, state);
  else if (data.kind === 'detect') detectPage(data, state);
  else fail('Unknown report kind: ' + data.kind);
} catch (e) {
  // Without WebGL the 3-D view cannot be shown; the rest of the page still is.
  state.webgl = !!window.WebGLRenderingContext && !/WebGL/i.test(String(e && e.message));
  fail('The 3-D view could not be shown: ' + (e && e.message ? e.message : e));
}
