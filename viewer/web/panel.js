// The panel's tables and lists: the model, the tools, the rates, the events.

function cell(text, cls) { const td = document.createElement('td'); td.textContent = text; if (cls) td.className = cls; return td; }
function row(...cells) { const tr = document.createElement('tr'); tr.append(...cells); return tr; }
const fixed = (v, digits) => (Number.isFinite(v) ? v.toFixed(digits) : '–');
const MAX_EVENTS_SHOWN = 8;

export function renderModel(m) {
  document.getElementById('model').textContent =
    `${m.model_id}: ${m.vertex_count} surface vertices (${m.compliance_vertex_count} free), ` +
    `${m.triangle_count} triangles · ${m.material} · ` +
    (m.mechanics === 'warped' ? 'warped (large rotations)' : 'linear') +
    (m.cut_region ? ` · cut region ${m.cut_region}` : '');
}

/** The tools table; each tool's name in the colour of its contact points (colourOf(id), 0xRRGGBB). */
export function renderToolTable(list, colourOf) {
  const body = document.querySelector('#tools tbody');
  const name = (id) => {
    const td = cell(`● ${id}`);
    td.style.color = `#${colourOf(id).toString(16).padStart(6, '0')}`;
    return td;
  };
  body.replaceChildren(row(cell('tool'), cell('state'), cell('|F| N', 'num'), cell('contacts', 'num'), cell('grip N', 'num')),
    ...list.map((t) => row(name(t.tool_id), cell(t.watchdog ? 'watchdog' : t.state, `state-${t.state}`),
      cell(fixed(Math.hypot(...t.force), 3), 'num'), cell(String(t.contacts), 'num'), cell(fixed(t.grip_force, 2), 'num'))));
}

/** The rates table: the page's own (`page`, per second) and the bridge's and daemon's (`status`). */
export function renderRates(page, status) {
  const d = status?.daemon, b = status?.bridge;
  const rows = [
    ['page frames / s', fixed(page.fps, 0)],
    ['surface frames drawn / s', fixed(page.surfaces, 0)],
    ['tool updates / s', fixed(page.tools, 0)],
    ['bridge: surfaces / s', fixed(b?.surface_hz, 0)],
    ['bridge: poses / s', fixed(b?.pose_hz, 0)],
    ['bridge: feedback / s', fixed(b?.feedback_hz, 0)],
    ['daemon: surface Hz', fixed(d?.surface_rate_hz, 0)],
    ['daemon: requests / s', fixed(d?.request_rate_hz, 0)],
    ['daemon: tool tick p50 / p99 µs', d ? `${fixed(d.tool_compute.p50_us, 0)} / ${fixed(d.tool_compute.p99_us, 0)}` : '–'],
  ];
  document.querySelector('#rates tbody').replaceChildren(...rows.map(([k, v]) => row(cell(k), cell(v, 'num'))));
}

/** "1 point held", "3 points held": a grasp's held points, as palpate-pliers says it. */
function heldPoints(n) {
  return `${n} point${n === 1 ? '' : 's'} held`;
}

/** Adds an event or warning message at the top of the list; returns its text. */
export function addEvent(e) {
  const text = e.type === 'warning' ? `warning: ${e.message}`
    : `${e.tool_id}: ${e.kind}${e.kind === 'grasp' ? ` (${heldPoints(e.held_vertices)})` : ''}`;
  const list = document.getElementById('events');
  const li = document.createElement('li');
  li.textContent = text;
  list.prepend(li);
  while (list.children.length > MAX_EVENTS_SHOWN) list.lastChild.remove();
  return text;
}
