// Summary cards, notes, the plane info table and the configuration block.

/// `value * scale` with `digits` decimals (integers as they are).
export function fmt(value, scale = 1, digits = null) {
  if (typeof value !== 'number' || !isFinite(value)) return String(value);
  const v = value * scale;
  if (digits === null) return Number.isInteger(v) ? String(v) : v.toPrecision(4);
  return v.toFixed(digits);
}

function escapeHtml(text) {
  return String(text).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' }[c]));
}

/// Cards of {label, key, value, scale, digits, unit, text}; each value element carries data-key
/// (where the figure comes from), data-value (the exact figure) and data-scale, for the tests.
export function statGrid(container, stats) {
  for (const s of stats) {
    if (s.value === undefined || s.value === null) continue;
    const card = document.createElement('div');
    card.className = 'stat';
    const k = document.createElement('div');
    k.className = 'k';
    k.textContent = s.label;
    const v = document.createElement('span');
    v.className = 'v';
    v.dataset.key = s.key;
    v.dataset.value = JSON.stringify(s.value);
    v.dataset.scale = String(s.scale || 1);
    v.textContent = s.text ? String(s.value) : fmt(s.value, s.scale || 1, s.digits ?? null);
    if (s.text) v.style.fontSize = '13px';
    card.append(k, v);
    if (s.unit) {
      const u = document.createElement('span');
      u.className = 'u';
      u.textContent = s.unit;
      card.appendChild(u);
    }
    container.appendChild(card);
  }
}

export function showNotes(notes) {
  const ul = document.getElementById('notes');
  for (const n of notes) {
    const li = document.createElement('li');
    li.textContent = n;
    ul.appendChild(li);
  }
}

export function showConfig(yaml) {
  if (!yaml) return;
  document.getElementById('config-text').textContent = yaml;
  document.getElementById('config-section').hidden = false;
}

const vec = (v, d = 3) => '(' + v.map((x) => x.toFixed(d)).join(', ') + ')';

/// Parameters of a plane_map.json plane as an HTML table.
export function planeInfoTable(p) {
  const rows = [
    ['plane', `<b>${p.id}</b>`],
    ['normal', vec(p.normal)],
    ['d', `${p.d.toFixed(3)} m`],
    ['area', `${p.area.toFixed(3)} m&sup2;` + (p.polygons.length > 1 ? ` (${p.polygons.length} parts)` : '')],
    ['observed area', `${(p.observed_area ?? 0).toFixed(3)} m&sup2;`],
    ['observations', String(p.observations)],
    ['points', String(p.point_count)],
    ['rms', `${(1000 * p.rms).toFixed(1)} mm`],
    ['keyframes', `${p.first_frame} to ${p.last_frame}`],
  ];
  return '<table>' + rows.map(([k, v]) => `<tr><td>${escapeHtml(k)}</td><td>${v}</td></tr>`).join('') + '</table>';
}
