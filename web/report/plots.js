// 2-D plots: the run's own SVG files inlined, and SVG charts drawn here from frames.csv and the
// summary's stage times.

export function inlineSvg(container, title, svgText) {
  const div = document.createElement('div');
  div.className = 'plot';
  const h = document.createElement('h3');
  h.textContent = title;
  div.appendChild(h);
  const holder = document.createElement('div');
  holder.innerHTML = svgText.replace(/^<\?xml[^>]*>\s*/, '');
  const svg = holder.querySelector('svg');
  if (svg && !svg.getAttribute('viewBox') && svg.getAttribute('width') && svg.getAttribute('height')) {
    svg.setAttribute('viewBox', `0 0 ${parseFloat(svg.getAttribute('width'))} ${parseFloat(svg.getAttribute('height'))}`);
  }
  div.appendChild(holder);
  container.appendChild(div);
}

function parseCsv(text) {
  const lines = text.trim().split('\n');
  const header = lines[0].split(',');
  return lines.slice(1).map((line) => {
    const cells = line.split(',');
    const row = {};
    header.forEach((h, i) => { row[h] = cells[i]; });
    return row;
  });
}

const W = 720, H = 220, L = 48, R = 12, T = 12, B = 30;

function axes(xmax, ymax, xlabel, ylabel, left = L, yTicks = true, right = R) {
  const parts = [];
  const nice = (m) => { const p = Math.pow(10, Math.floor(Math.log10(m || 1))); return [1, 2, 5, 10].map((k) => k * p).find((s) => m / s <= 6); };
  const ys = nice(ymax), xs = nice(xmax);
  for (let y = 0; yTicks && y <= ymax + 1e-9; y += ys) {
    const py = T + (H - T - B) * (1 - y / ymax);
    parts.push(`<line x1="${left}" x2="${W - right}" y1="${py}" y2="${py}" stroke="#e3e6ea"/>`);
    parts.push(`<text x="${left - 6}" y="${py + 4}" text-anchor="end" font-size="11" fill="#5c6670">${+y.toFixed(6)}</text>`);
  }
  for (let x = 0; x <= xmax + 1e-9; x += xs) {
    const px = left + (W - left - right) * (x / xmax);
    parts.push(`<text x="${px}" y="${H - B + 15}" text-anchor="middle" font-size="11" fill="#5c6670">${+x.toFixed(6)}</text>`);
  }
  parts.push(`<text x="${(left + W - right) / 2}" y="${H - 3}" text-anchor="middle" font-size="11" fill="#5c6670">${xlabel}</text>`);
  parts.push(`<text x="11" y="${(T + H - B) / 2}" text-anchor="middle" font-size="11" fill="#5c6670" transform="rotate(-90 11 ${(T + H - B) / 2})">${ylabel}</text>`);
  parts.push(`<rect x="${left}" y="${T}" width="${W - left - right}" height="${H - T - B}" fill="none" stroke="#b9c0c8"/>`);
  return parts.join('');
}

function chart(container, title, body, legend) {
  const div = document.createElement('div');
  div.className = 'plot';
  div.innerHTML = `<h3>${title}</h3><svg viewBox="0 0 ${W} ${H}" xmlns="http://www.w3.org/2000/svg" font-family="sans-serif">${body}</svg>` +
    (legend ? `<div style="font-size:12px;color:#5c6670">${legend}</div>` : '');
  container.appendChild(div);
}

const sw = (c) => `<span style="display:inline-block;width:10px;height:10px;background:${c};margin:0 4px 0 10px"></span>`;

/// Planes and matches per frame as lines, keyframes, degenerate, untracked, loop-closure and
/// skipped frames as tick rows under them.
export function framePlots(container, csv) {
  const rows = parseCsv(csv);
  if (rows.length === 0) return;
  const idx = rows.map((r) => +r.index);
  const xmax = Math.max(1, ...idx);
  const num = (r, k) => (r[k] === '' || r[k] === undefined ? null : +r[k]);
  const ymax = Math.max(1, ...rows.map((r) => Math.max(num(r, 'planes') || 0, num(r, 'matches') || 0))) * 1.1;
  const px = (i) => L + (W - L - R) * (i / xmax);
  const py = (v) => T + (H - T - B) * (1 - v / ymax);
  const path = (k) => {
    let d = '', pen = false;
    for (const r of rows) {
      const v = num(r, k);
      if (v === null) { pen = false; continue; }
      d += `${pen ? 'L' : 'M'}${px(+r.index).toFixed(1)},${py(v).toFixed(1)}`;
      pen = true;
    }
    return d;
  };
  chart(container, 'Planes and matches per frame (frames.csv)',
    axes(xmax, ymax, 'frame index', 'count') +
    `<path d="${path('planes')}" fill="none" stroke="#2a6fdb" stroke-width="1.2"/>` +
    `<path d="${path('matches')}" fill="none" stroke="#e0660f" stroke-width="1.2"/>`,
    `${sw('#2a6fdb')}planes detected ${sw('#e0660f')}planes matched to the map`);

  const flags = [
    ['keyframe', (r) => r.keyframe === '1', '#e0660f'],
    ['degenerate', (r) => r.degenerate === '1', '#8a58c8'],
    ['point-to-plane', (r) => r.point_to_plane === '1', '#2a9d8f'],
    ['untracked', (r) => r.status === 'ok' && r.tracked === '0', '#777777'],
    ['loop closure', (r) => +r.loop_closures > 0, '#c0158f'],
    ['refused', (r) => r.refused === '1', '#d4a017'],
    ['skipped / stopped', (r) => r.status !== 'ok', '#d62728'],
  ];
  const rowH = (H - T - B) / flags.length;
  const left = 110, right = 44;
  const fx = (i) => left + (W - left - right) * (i / xmax);
  let body = axes(xmax, 1, 'frame index', '', left, false, right);
  flags.forEach(([name, test, colour], k) => {
    const y = T + k * rowH;
    body += `<text x="${left - 4}" y="${y + rowH * 0.7}" text-anchor="end" font-size="10" fill="#5c6670">${name}</text>`;
    let count = 0;
    for (const r of rows) {
      if (!test(r)) continue;
      ++count;
      body += `<rect x="${fx(+r.index).toFixed(1)}" y="${(y + 2).toFixed(1)}" width="${Math.max(1, (W - left - right) / xmax).toFixed(2)}" height="${(rowH - 4).toFixed(1)}" fill="${colour}"/>`;
    }
    body += `<text x="${W - 4}" y="${y + rowH * 0.7}" text-anchor="end" font-size="10" fill="#1d232b">${count}</text>`;
  });
  chart(container, 'Frame events (frames.csv; counts at the right)', body, null);
}

/// Mean time per frame of each stage (summary.json time_ms / frames), as horizontal bars.
export function stageTimePlot(container, timeMs, frames) {
  const entries = Object.entries(timeMs).map(([k, v]) => [k, v / Math.max(1, frames)]);
  const max = Math.max(1e-6, ...entries.map((e) => e[1]));
  const barH = (H - T - B) / entries.length;
  let body = '';
  entries.forEach(([k, v], i) => {
    const y = T + i * barH;
    const w = (W - 160 - R) * (v / max);
    body += `<text x="96" y="${y + barH * 0.65}" text-anchor="end" font-size="11" fill="#5c6670">${k}</text>`;
    body += `<rect x="100" y="${y + 3}" width="${w.toFixed(1)}" height="${(barH - 6).toFixed(1)}" fill="#2a6fdb"/>`;
    body += `<text x="${104 + w}" y="${y + barH * 0.65}" font-size="11" fill="#1d232b">${v.toFixed(2)} ms</text>`;
  });
  chart(container, 'Time per frame by stage (summary.json time_ms / frames)', body, null);
}
