// inhand eval index: the results table and, per object, coverage against views for every planner
// (mean over seeds), with links to each run's report. Data: window.INHAND_DATA.
const D = window.INHAND_DATA;
const state = { charts: {}, ready: false };
window.inhandReport = state;

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
}

const app = document.getElementById('app');
app.append(el('header', {}, el('h1', {}, 'inhand eval')));
const main = el('main');
app.append(main);

// Markdown (as results.md writes it: headings, paragraphs, pipe tables) to HTML.
function markdown(md) {
  const out = el('div');
  let table = null;
  for (const line of md.split('\n')) {
    if (line.startsWith('|')) {
      const cells = line.split('|').slice(1, -1).map((c) => c.trim());
      if (cells.every((c) => /^-+$/.test(c))) continue;
      if (!table) { table = el('table'); out.append(table); table.append(el('tr', {}, ...cells.map((c) => el('th', {}, c)))); continue; }
      table.append(el('tr', {}, ...cells.map((c) => el('td', {}, c))));
      continue;
    }
    table = null;
    if (line.startsWith('## ')) out.append(el('h2', { style: 'margin-top:12px' }, line.slice(3)));
    else if (line.startsWith('# ')) continue;
    else if (line.trim()) out.append(el('p', {}, line));
  }
  return out;
}
const results = el('section', {}, el('h2', {}, 'Results'));
results.append(markdown(D.results_md));
main.append(results);

const colors = ['#c0392b', '#2471a3', '#229954', '#b7950b', '#7d3c98', '#ca6f1e', '#566573', '#17a589'];
const objects = [...new Set(D.curves.map((c) => c.object))];
const planners = [...new Set(D.curves.map((c) => c.planner))];
const curves = el('section', {}, el('h2', {}, 'Coverage against views (mean over seeds)'));
main.append(curves);
const row = el('div', { class: 'row' });
curves.append(row);
for (const o of objects) {
  const runs = D.curves.filter((c) => c.object === o);
  const n = Math.max(...runs.map((r) => r.coverage.length));
  const datasets = planners.map((p, i) => {
    const rs = runs.filter((r) => r.planner === p);
    const data = [];
    for (let v = 0; v < n; ++v) {
      // A run that ended keeps its final coverage for the later views.
      const xs = rs.map((r) => (r.coverage.length ? r.coverage[Math.min(v, r.coverage.length - 1)] : NaN)).filter((x) => x >= 0);
      data.push(xs.length ? (100 * xs.reduce((a, b) => a + b, 0)) / xs.length : null);
    }
    return { label: p, data, borderColor: colors[i % colors.length], backgroundColor: colors[i % colors.length], pointRadius: 2, tension: 0 };
  });
  const box = el('div', { class: 'chart' });
  const c = el('canvas', { id: 'cov-' + o });
  box.append(c);
  row.append(box);
  new Chart(c, { type: 'line', data: { labels: [...Array(n).keys()].map((k) => k + 1), datasets },
    options: { animation: false, responsive: true, maintainAspectRatio: false,
               plugins: { title: { display: true, text: o } },
               scales: { x: { title: { display: true, text: 'views' } }, y: { title: { display: true, text: 'coverage %' } } } } });
  state.charts['cov-' + o] = datasets.map((d) => d.data.length);
}

const links = el('section', {}, el('h2', {}, 'Runs'));
main.append(links);
for (const o of objects) {
  const p = el('p', {}, el('b', {}, o + ': '));
  for (const r of D.curves.filter((c) => c.object === o)) {
    p.append(el('a', { href: r.report }, `${r.planner} seed ${r.seed}`), ' ');
  }
  links.append(p);
}
state.ready = true;
window.inhandSelfTest({ charts: state.charts, rows: document.querySelectorAll('table tr').length });
