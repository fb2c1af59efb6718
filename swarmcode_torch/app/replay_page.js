"use strict";
// The replay page of swarmcode-torch (app/replay_page.py writes the data; no network, no libraries).
(function () {
  const PINCHER = 1, DELIVERED = 2;
  const MIN_R = 4.5;   // css px: the smallest robot disc drawn (a 0.15 m robot of a 60 m arena is ~1 px)
  const STATUS = ["SUCCESS", "FAILURE", "RUNNING"];
  const PANELS = ["focal", "baseline"];
  const $ = (id) => document.getElementById(id);
  // every run-data value that reaches innerHTML goes through esc (the page's CSP forbids inline handlers too)
  const esc = (s) => String(s).replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c]));
  const fmt = (x, d) => (x === null || x === undefined || Number.isNaN(x)) ? "–" : Number(x).toFixed(d);
  // scores: one decimal, more for the small scores of the roi objective
  const fmtS = (x) => fmt(x, x !== null && x !== undefined && Math.abs(x) < 10 ? 3 : 1);

  function fail(msg) {
    const e = $("error");
    e.hidden = false;
    e.textContent = msg;
    $("subtitle").textContent = "";
  }

  async function loadData() {
    const b64 = $("episode-data").textContent.trim();
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    if (typeof DecompressionStream === "undefined") {
      throw new Error("this browser cannot inflate the page's data (no DecompressionStream); " +
                      "open the file in a current Chrome, Edge, Firefox or Safari");
    }
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("gzip"));
    return JSON.parse(await new Response(stream).text());
  }

  // cumulative sum along ticks of a delta-coded flat array of frames of `frame` values
  function undelta(a, frame, scale) {
    const out = new Float64Array(a.length);
    for (let i = 0; i < a.length; i++) out[i] = i < frame ? a[i] : out[i - frame] + a[i];
    if (scale !== 1) for (let i = 0; i < out.length; i++) out[i] /= scale;
    return out;
  }

  function prepare(D) {
    const N = D.robots, Q = D.Q, G = D.G;
    for (const name of PANELS) {
      const p = D.panels[name];
      p.posA = undelta(p.pos, N * 2, 100);
      p.energyA = undelta(p.energy, N, 10);
      p.pposA = undelta(p.p_pos, Q * 2, 100);
      // each pick-up and delivery: [tick, robot, package, kind] (kind: 0 delivered individual,
      // 1 delivered collaborative, 2 picked individual, 3 picked collaborative)
      p.cred = [];
      for (let i = 0; i + 3 < (p.credits || []).length; i += 4) p.cred.push(p.credits.slice(i, i + 4));
      // per tick counts, as episode_metrics counts them at the end
      p.counts = [];
      for (let t = 0; t <= D.ticks; t++) {
        const c = {di: 0, dc: 0, pi: 0, pc: 0};
        for (let q = 0; q < Q; q++) {
          if (!D.packages.present[q]) continue;
          const col = D.packages.collab[q];
          if (p.p_status[t * Q + q] === DELIVERED) col ? c.dc++ : c.di++;
          if (p.p_picked[t * Q + q]) col ? c.pc++ : c.pi++;
        }
        p.counts.push(c);
      }
    }
    D.total = D.packages.present.reduce((a, b) => a + b, 0);
    D.nCollab = D.packages.collab.reduce((a, c, q) => a + (c && D.packages.present[q] ? 1 : 0), 0);
    D.G = G;
  }

  // ------------------------------------------------------------------ drawing
  const view = {};   // panel -> {canvas, ctx, scale, px}

  function resize(D) {
    for (const name of PANELS) {
      const cv = $("canvas-" + name);
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(120, Math.round(cv.getBoundingClientRect().width));
      cv.width = Math.round(w * dpr);
      cv.height = Math.round(w * dpr);
      view[name] = {canvas: cv, ctx: cv.getContext("2d"), css: w, dpr: dpr,
                    s: (w * dpr) / (D.arena + 0.4)};
    }
  }

  function toPx(v, x, y, D) { return [(x + 0.2) * v.s, (D.arena + 0.2 - y) * v.s]; }

  function hexagon(ctx, x, y, r) {
    ctx.beginPath();
    for (let k = 0; k < 6; k++) {
      const a = Math.PI / 2 + k * Math.PI / 3;
      ctx[k ? "lineTo" : "moveTo"](x + r * Math.cos(a), y - r * Math.sin(a));
    }
    ctx.closePath();
  }

  function shape(ctx, eff, x, y, r) {   // square: pincher, circle: suction
    ctx.beginPath();
    if (eff === PINCHER) ctx.rect(x - r * 0.9, y - r * 0.9, 1.8 * r, 1.8 * r);
    else ctx.arc(x, y, r, 0, 2 * Math.PI);
  }

  function draw(D, name, t) {
    const v = view[name], ctx = v.ctx, p = D.panels[name], s = v.s, N = D.robots, Q = D.Q, G = D.G;
    const pk = D.packages, lw = Math.max(1, v.dpr);
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, v.canvas.width, v.canvas.height);
    let [x0, y0] = toPx(v, 0, D.arena, D);
    ctx.fillStyle = "#fff"; ctx.strokeStyle = "#000"; ctx.lineWidth = 1.2 * lw;
    ctx.fillRect(x0, y0, D.arena * s, D.arena * s); ctx.strokeRect(x0, y0, D.arena * s, D.arena * s);
    const [bx, by] = toPx(v, D.arena / 2, D.arena / 2, D);
    ctx.beginPath(); ctx.arc(bx, by, D.base_radius * s, 0, 2 * Math.PI);
    ctx.fillStyle = "#cfeccf"; ctx.fill(); ctx.strokeStyle = "#3a8a3a"; ctx.lineWidth = lw; ctx.stroke();
    for (const [ox, oy, r] of D.obstacles) {
      const [x, y] = toPx(v, ox, oy, D);
      ctx.beginPath(); ctx.arc(x, y, r * s, 0, 2 * Math.PI);
      ctx.fillStyle = "#9a9a9a"; ctx.fill(); ctx.strokeStyle = "#555"; ctx.lineWidth = 0.8 * lw; ctx.stroke();
    }
    // delivered packages so far, as a count inside the base
    const c = p.counts[t], nd = c.di + c.dc;
    ctx.fillStyle = "#2f6f2f"; ctx.font = `${Math.max(10, Math.round(0.55 * D.base_radius * s))}px system-ui, sans-serif`;
    ctx.textAlign = "center"; ctx.textBaseline = "middle";
    ctx.fillText(String(nd), bx, by);
    const carried = [], grips = [];
    for (let q = 0; q < Q; q++) {
      if (!pk.present[q] || p.p_status[t * Q + q] === DELIVERED) continue;
      const px = p.pposA[(t * Q + q) * 2], py = p.pposA[(t * Q + q) * 2 + 1];
      const [x, y] = toPx(v, px, py, D);
      const size = pk.size[q];
      let held = -1;
      for (let g = 0; g < G; g++) if (p.holder[(t * Q + q) * G + g] >= 0) { held = p.holder[(t * Q + q) * G + g]; break; }
      if (pk.collab[q]) {
        hexagon(ctx, x, y, size * 1.05 * s);
        ctx.fillStyle = pk.color[q]; ctx.fill(); ctx.strokeStyle = "#000"; ctx.lineWidth = 0.6 * lw; ctx.stroke();
        for (let g = 0; g < G; g++) {
          const e = pk.g_eff[q * G + g];
          if (e < 0) continue;
          const gx = px + pk.g_off[(q * G + g) * 2], gy = py + pk.g_off[(q * G + g) * 2 + 1];
          grips.push([e, gx, gy, p.holder[(t * Q + q) * G + g] >= 0]);
        }
      } else if (held >= 0) {
        carried.push([q, x, y, Math.min(size, 0.45 * D.panels[name].robots.radius[held]), held]);
      } else {
        shape(ctx, pk.g_eff[q * G], x, y, size * s);
        ctx.fillStyle = pk.color[q]; ctx.fill(); ctx.strokeStyle = "#000"; ctx.lineWidth = 0.6 * lw; ctx.stroke();
      }
    }
    // robots
    const R = p.robots;
    for (let i = 0; i < N; i++) {
      const d = R.design[i];
      if (d < 0) continue;
      const [x, y] = toPx(v, p.posA[(t * N + i) * 2], p.posA[(t * N + i) * 2 + 1], D);
      const r = Math.max(MIN_R * v.dpr, R.radius[i] * s);
      const carrying = p.holding[t * N + i] >= 0;
      ctx.globalAlpha = p.energyA[t * N + i] > 0.0001 ? 1 : 0.3;
      ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI);
      ctx.fillStyle = D.designs[d].color; ctx.fill();
      ctx.strokeStyle = carrying ? "#000" : "#444"; ctx.lineWidth = (carrying ? Math.min(2, Math.max(1, r / v.dpr / 5)) : 0.6) * lw; ctx.stroke();
      ctx.beginPath();
      if (R.effector[i] === PINCHER) { const h = 0.42 * r; ctx.rect(x - h, y - h, 2 * h, 2 * h); }
      else ctx.arc(x, y, 0.48 * r, 0, 2 * Math.PI);
      ctx.strokeStyle = "#1a1a1a"; ctx.lineWidth = 0.9 * lw; ctx.stroke();
      ctx.globalAlpha = 1;
    }
    for (const [q, x, y, r, held] of carried) {   // small, on its carrier, so its colour shows
      const rr = Math.max(MIN_R * v.dpr, R.radius[held] * s);
      if (rr < 7 * v.dpr) continue;   // too small to show both: the black outline says it
      shape(ctx, pk.g_eff[q * G], x, y, Math.min(0.45 * rr, Math.max(1.5 * v.dpr, r * s)));
      ctx.fillStyle = pk.color[q]; ctx.fill(); ctx.strokeStyle = "#000"; ctx.lineWidth = 0.6 * lw; ctx.stroke();
    }
    for (const [e, gx, gy, taken] of grips) {
      const [x, y] = toPx(v, gx, gy, D);
      const h = (taken ? 0.07 : 0.11) * s;
      ctx.beginPath();
      if (e === PINCHER) ctx.rect(x - h, y - h, 2 * h, 2 * h); else ctx.arc(x, y, h * 1.1, 0, 2 * Math.PI);
      ctx.fillStyle = taken ? "#000" : "#fff"; ctx.fill(); ctx.strokeStyle = "#000"; ctx.lineWidth = 0.7 * lw; ctx.stroke();
    }
    if (state.sel && state.sel.panel === name) {
      const i = state.sel.robot;
      const [x, y] = toPx(v, p.posA[(t * N + i) * 2], p.posA[(t * N + i) * 2 + 1], D);
      const r = Math.max(MIN_R * v.dpr, R.radius[i] * s) + 4 * v.dpr;
      ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI);
      ctx.setLineDash([4 * v.dpr, 3 * v.dpr]); ctx.strokeStyle = "#c2185b"; ctx.lineWidth = 2.5 * v.dpr; ctx.stroke();
      ctx.setLineDash([]);
    }
  }

  // ------------------------------------------------------------------ text
  function designLabel(D, d) {
    const g = D.designs[d];
    return `sp ${g.species} ${g.effector} r=${fmt(g.radius, 2)}`;
  }

  function swatch(D, d, size) {
    const g = D.designs[d], r = size / 2 - 1, c = size / 2;
    const mark = g.effector === "pincher"
      ? `<rect x="${c - 0.42 * r}" y="${c - 0.42 * r}" width="${0.84 * r}" height="${0.84 * r}" fill="none" stroke="#1a1a1a"/>`
      : `<circle cx="${c}" cy="${c}" r="${0.48 * r}" fill="none" stroke="#1a1a1a"/>`;
    return `<svg class="swatch" width="${size}" height="${size}" aria-hidden="true"><circle cx="${c}" cy="${c}" r="${r}" fill="${esc(g.color)}" stroke="#444" stroke-width="0.8"/>${mark}</svg>`;
  }

  function liveText(D, name, t) {
    const p = D.panels[name], c = p.counts[t], nd = c.di + c.dc;
    if (!p.robots.design.some((d) => d >= 0)) return `no robot: the team has no partner (delivered <b data-testid="delivered-${name}">0</b>/${esc(D.total)})`;
    const collab = D.nCollab ? ` (${esc(c.di)} indiv, ${esc(c.dc)} collab)` : "";
    const energy = 100 - p.team_energy[t];
    return `delivered <b data-testid="delivered-${name}">${esc(nd)}</b>/${esc(D.total)}${collab} · picked ` +
           `<b data-testid="picked-${name}">${esc(c.pi + c.pc)}</b> · energy used ` +
           `<b data-testid="energy-${name}">${fmt(energy, 2)}</b>%`;
  }

  function summaryHtml(D) {
    const f = D.panels.focal, b = D.panels.baseline, g = D.designs[D.focal];
    const m = D.marginal, cls = m > 0 ? "pos" : "neg";
    const kept = Math.abs(D.gated - f.score) < 1e-9 ? "the focal's score, kept"
      : `the focal's score &times; ${esc(D.p_marginal)}: it does not beat its baseline`;
    const rec = D.record || {};
    const recTxt = rec.fitness !== undefined && rec.fitness !== null
      ? ` The run recorded a fitness of ${fmtS(rec.fitness)} for this team` +
        (rec.generation !== undefined ? ` in generation ${esc(rec.generation)}` : "") +
        (rec.trials !== undefined
          ? ` (its mean over ${esc(rec.trials)} fresh environments` +
            (rec.fitness_low !== undefined && rec.fitness_high !== undefined
              ? `, 95 % interval ${fmtS(rec.fitness_low)} to ${fmtS(rec.fitness_high)}` : "") +
            "; this page is one episode)."
          : " (a mean over the run's trials; this page is one episode).") : "";
    return `<b>Focal individual:</b> ${swatch(D, D.focal, 14)} ${esc(designLabel(D, D.focal))} ` +
      `(${esc(g.count)} of ${esc(D.robots)} robots). Focal team score <b data-testid="focal-score">${fmtS(f.score)}</b>, ` +
      `baseline team score <b data-testid="baseline-score">${fmtS(b.score)}</b> ` +
      (b.robots.design.some((d) => d >= 0)
        ? `(the focal's ${esc(g.count)} slots refilled by its partners` +
          (D.baseline_recorded ? ", as the run recorded them" : ", drawn by dominance: the run did not record its baseline") + ")"
        : "(the team has no partner to refill the focal's slots: the baseline team has no robot)") +
      `, marginal contribution ` +
      `<b class="${cls}" data-testid="marginal">${m >= 0 ? "+" : ""}${fmtS(m)}</b>; ` +
      `gated fitness ${fmtS(D.gated)} (${kept}).${recTxt}` + seedsText(D) +
      (D.custom_fitness ? ` <br><b>Note:</b> the run was scored by ${esc(D.custom_fitness)}; the scores here are the built-in fitness.` : "");
  }

  function seedsText(D) {   // replay --seeds N: the same two teams in N environments
    const sm = D.seed_marginals;
    if (!sm) return "";
    const n = sm.marginal.length, beat = sm.marginal.filter((x) => x > 0).length;
    return ` Over ${esc(n)} environments (seeds ${esc(sm.seeds[0])}–${esc(sm.seeds[1])}) the marginal contribution is ` +
      `<b data-testid="mean-marginal">${sm.mean >= 0 ? "+" : ""}${fmtS(sm.mean)}</b> on average` +
      (sm.sd !== null ? ` (sd ${fmtS(sm.sd)})` : "") + `; the focal's team beats its baseline in ${esc(beat)} of them.`;
  }

  function legendHtml(D) {
    let h = `<h3>Designs</h3><table><tr><th></th><th>design</th><th class="num">focal</th><th class="num">baseline</th></tr>`;
    D.designs.forEach((g, d) => {
      h += `<tr><td>${swatch(D, d, 16)}</td><td>${esc(designLabel(D, d))}` +
           (g.focal ? ` <span class="focal-star" title="the focal individual">★ focal</span>` : "") +
           `</td><td class="num">${esc(g.count)}</td><td class="num">${esc(g.baseline_count)}</td></tr>`;
    });
    h += `</table><p class="muted">Robots: discs of their true radius in their design's colour; an inner square: pincher, ` +
         `an inner ring: suction (at least 4 px across); black outline: carrying, with its package drawn small on top; faded: battery flat. Packages: squares need a pincher, ` +
         `circles suction, darker is heavier; hexagons are collaborative, with a marker per grip point ` +
         `(white: free, black: held). The number in the base: packages delivered. Hover over a robot or a package for what it is.</p>`;
    h += `<h3>Package classes</h3><ul class="muted">` + D.classes.map((c, i) => `<li>${i}: ${esc(c)}</li>`).join("") + `</ul>`;
    return h;
  }

  function termsHtml(D) {
    const f = D.panels.focal, b = D.panels.baseline;
    const rows = [["delivery", "deliveries"], ["collab", "collaborative deliveries + bonus"], ["pickup", "pick-ups"],
                  ["energy", "energy left"], ["proximity", "proximity"], ["closeness", "closeness"]];
    let h = `<h3>Fitness terms at the end (tick ${esc(D.ticks)})</h3><table><tr><th>term</th><th class="num">focal</th><th class="num">baseline</th></tr>`;
    for (const [k, label] of rows)
      h += `<tr><td>${label}</td><td class="num">${fmt(f.terms[k], 2)}</td><td class="num">${fmt(b.terms[k], 2)}</td></tr>`;
    h += `<tr><td>× activity (inactive factor if nothing was picked up)</td><td class="num">${fmt(f.terms.activity, 2)}</td><td class="num">${fmt(b.terms.activity, 2)}</td></tr>`;
    h += `<tr class="total"><td>F<sub>raw</sub> (at least ${fmt(f.floor, 2)})</td><td class="num">${fmt(Math.max(f.raw, f.floor), 2)}</td><td class="num">${fmt(Math.max(b.raw, b.floor), 2)}</td></tr>`;
    h += `<tr><td>team cost ($)${D.budget !== null ? `, budget $${fmt(D.budget, 0)}` : ""}</td><td class="num">${fmt(f.cost, 0)}</td><td class="num">${fmt(b.cost, 0)}</td></tr>`;
    h += `<tr><td>× budget penalty</td><td class="num">${fmt(f.penalty, 3)}</td><td class="num">${fmt(b.penalty, 3)}</td></tr>`;
    if (D.objective === "roi") h += `<tr><td>÷ cost (objective: roi)</td><td class="num">${fmt(f.cost, 0)}</td><td class="num">${fmt(b.cost, 0)}</td></tr>`;
    h += `<tr class="total"><td>score</td><td class="num">${fmt(f.score, 2)}</td><td class="num">${fmt(b.score, 2)}</td></tr></table>`;
    const mm = (p) => p.metrics;
    h += `<table style="margin-top:8px"><tr><th>metric (episode_metrics)</th><th class="num">focal</th><th class="num">baseline</th></tr>`;
    for (const [k, label, d] of [["delivered_individual", "delivered, individual", 0], ["delivered_collab", "delivered, collaborative", 0],
                                 ["grips_delivered", "grips delivered", 0], ["picked_individual", "picked, individual", 0],
                                 ["picked_collab", "picked, collaborative", 0], ["energy_used", "energy used (%)", 2],
                                 ["proximity", "proximity", 3], ["closeness", "closeness", 3]])
      h += `<tr><td>${label}</td><td class="num" data-testid="metric-focal-${k}">${fmt(mm(f)[k], d)}</td><td class="num" data-testid="metric-baseline-${k}">${fmt(mm(b)[k], d)}</td></tr>`;
    return h + "</table>";
  }

  // credits up to tick t: per robot and per design, [delivered, of them collaborative, picked, of them collaborative]
  function creditCounts(D, name, t) {
    const p = D.panels[name], robot = [], design = D.designs.map(() => [0, 0, 0, 0]);
    for (let i = 0; i < D.robots; i++) robot.push([0, 0, 0, 0]);
    for (const [tk, r, , k] of p.cred) {
      if (tk > t) break;
      const col = k < 2 ? 0 : 2, d = p.robots.design[r];
      robot[r][col]++; if (k % 2) robot[r][col + 1]++;
      if (d >= 0) { design[d][col]++; if (k % 2) design[d][col + 1]++; }
    }
    return {robot, design};
  }

  const credCell = (c, col, id) => `<td class="num" data-testid="${id}">${esc(c[col])}` +
    (c[col + 1] ? `<span class="muted"> (${esc(c[col + 1])} collab)</span>` : "") + `</td>`;

  function creditsHtml(D, t) {
    const f = creditCounts(D, "focal", t), b = creditCounts(D, "baseline", t);
    const F = D.panels.focal.robots.design, B = D.panels.baseline.robots.design;
    const head = `<tr><th></th><th colspan="3">focal arena</th><th colspan="3">baseline arena</th></tr>`;
    let h = `<h3>Who picked up and delivered, to tick <span data-testid="credits-tick">${esc(t)}</span></h3>` +
      `<table data-testid="credits-design">${head}<tr><th>design</th><th class="num">robots</th><th class="num">delivered</th>` +
      `<th class="num">picked up</th><th class="num">robots</th><th class="num">delivered</th><th class="num">picked up</th></tr>`;
    D.designs.forEach((g, d) => {
      const nf = F.filter((x) => x === d).length, nb = B.filter((x) => x === d).length;
      if (!nf && !nb) return;
      h += `<tr><td>${swatch(D, d, 14)} ${esc(designLabel(D, d))}</td><td class="num">${esc(nf)}</td>` +
           credCell(f.design[d], 0, `deliv-focal-d${d}`) + credCell(f.design[d], 2, `picked-focal-d${d}`) +
           `<td class="num">${esc(nb)}</td>` +
           credCell(b.design[d], 0, `deliv-baseline-d${d}`) + credCell(b.design[d], 2, `picked-baseline-d${d}`) + `</tr>`;
    });
    h += `</table><table data-testid="credits-robot" style="margin-top:8px">${head}<tr><th>robot</th>` +
         `<th>design</th><th class="num">delivered</th><th class="num">picked up</th>` +
         `<th>design</th><th class="num">delivered</th><th class="num">picked up</th></tr>`;
    const who = (ds, i) => ds[i] >= 0 ? `${swatch(D, ds[i], 12)} sp ${esc(D.designs[ds[i]].species)}` : "–";
    for (let i = 0; i < D.robots; i++) {
      if (F[i] < 0 && B[i] < 0) continue;
      h += `<tr><td class="num">${esc(i)}</td><td>${who(F, i)}</td>` +
           credCell(f.robot[i], 0, `deliv-focal-r${i}`) + credCell(f.robot[i], 2, `picked-focal-r${i}`) +
           `<td>${who(B, i)}</td>` +
           credCell(b.robot[i], 0, `deliv-baseline-r${i}`) + credCell(b.robot[i], 2, `picked-baseline-r${i}`) + `</tr>`;
    }
    return h + `</table><p class="muted">A delivery counts for every robot holding the package the tick before it ` +
      `was delivered (each carrier of a collaborative package); a pick-up for every robot holding a grip when the package ` +
      `was first lifted (as the metrics count pick-ups). The individual columns sum to the team's counts.</p>`;
  }

  function divergeHtml(D) {
    const v = D.divergence;
    if (v === null || v === undefined)
      return D.shared_slots ? `The two arenas never part in ${esc(D.ticks)} ticks: the focal's robots change nothing for the others.`
        : "The teams share no slot (the focal has no partner), so there is no tick at which the arenas part.";
    const d = D.panels.focal.robots.design[v.robot];
    return `The two arenas part at tick <b data-testid="divergence-tick">${esc(v.tick)}</b>: robot ${esc(v.robot)} ` +
      `(${swatch(D, d, 12)} ${esc(designLabel(D, d))}), in a slot both teams share, is first more than ` +
      `${fmt(D.divergence_eps * 1000, 0)} mm from where it is in the other arena. Before that, only the focal's slots differ; ` +
      `after it, small differences grow and the arenas are no longer comparable tick by tick. ` +
      `<button id="goto-divergence" type="button">Go to tick ${esc(v.tick)}</button>`;
  }

  function robotCredits(D, name, i, t) {
    const p = D.panels[name], dl = [], pk = [];
    for (const [tk, r, q, k] of p.cred) {
      if (tk > t) break;
      if (r === i) (k < 2 ? dl : pk).push(`#${esc(q)} at tick ${esc(tk)}`);
    }
    return `delivered ${dl.length ? dl.join(", ") : "none"}; picked up ${pk.length ? pk.join(", ") : "none"}`;
  }

  function inspectorHtml(D, t) {
    if (!state.sel) return `<h3>Robot</h3><p class="muted">Click a robot in either arena to see its design, energy, load and behavior tree.</p>`;
    const {panel, robot: i} = state.sel, p = D.panels[panel], N = D.robots, Q = D.Q, G = D.G;
    const d = p.robots.design[i], g = D.designs[d];
    const e = p.energyA[t * N + i], hold = p.holding[t * N + i];
    let holdTxt = "nothing";
    if (hold >= 0) {
      const pk = D.packages, cls = pk.cls[hold];
      const kind = pk.collab[hold] ? `collaborative, grip ${esc(p.grip[t * N + i])}` : "individual";
      const lifted = pk.collab[hold] && p.p_status[t * Q + hold] !== DELIVERED
        ? (Array.from({length: G}, (_, k) => pk.g_eff[hold * G + k] < 0 || p.holder[(t * Q + hold) * G + k] >= 0).every(Boolean) ? ", lifted" : ", waiting for the other grips") : "";
      holdTxt = `package #${esc(hold)} (${kind}${lifted}; class ${esc(cls)}: ${esc(D.classes[cls] || "?")}, ${fmt(pk.mass[hold], 1)} kg)`;
    }
    const can = g.capability ? (g.capability.length ? g.capability.map((c) => esc(D.classes[c] || c)).join("; ") : "no package class") : "–";
    let h = `<h3 data-testid="robot-title">${swatch(D, d, 16)} Robot ${esc(i)} of the ${esc(panel)} team: ${esc(designLabel(D, d))}` +
            (g.focal ? ` <span class="focal-star">★ focal</span>` : "") + `</h3>`;
    h += `<table class="kv" data-testid="robot-design">` +
      `<tr><td>species</td><td>${esc(g.species)}</td></tr>` +
      `<tr><td>effector</td><td>${esc(g.effector)}</td></tr>` +
      `<tr><td>radius</td><td>${fmt(g.radius, 3)} m</td></tr>` +
      `<tr><td>tiers</td><td>chassis ${esc(g.chassis_tier)}, battery ${esc(g.battery_tier)}, motor ${esc(g.motor_tier)}</td></tr>` +
      `<tr><td>operating points</td><td>torque ${fmt(g.torque_point, 2)}, battery ${fmt(g.battery_point, 2)}</td></tr>` +
      `<tr><td>cost</td><td>$${fmt(g.cost, 0)}</td></tr>` +
      `<tr><td>dominance</td><td>${fmt(g.dominance, 3)}${g.selectivity !== null && g.selectivity !== undefined ? ` (selectivity ${fmt(g.selectivity, 3)})` : ""}</td></tr>` +
      `<tr><td>lifts</td><td>${can}</td></tr>` +
      `<tr><td>mass, payload, force</td><td>${fmt(p.robots.mass[i], 1)} kg, ${fmt(p.robots.payload[i], 1)} kg, ${fmt(p.robots.force[i], 1)} N</td></tr>` +
      `<tr><td>energy (tick ${t})</td><td data-testid="robot-energy">${fmt(e, 1)}% of ${fmt(p.robots.capacity[i], 0)} J</td></tr>` +
      `<tr><td>holds</td><td data-testid="robot-holds">${holdTxt}</td></tr>` +
      `<tr><td>to tick ${t}</td><td data-testid="robot-credits">${robotCredits(D, panel, i, t)}</td></tr></table>`;
    // the behavior tree, as `inspect` prints it, with the nodes ticked at tick t
    let acting = -1, seen = new Map(), note;
    if (t === 0) note = "tick 0: no tree has run yet";
    else {
      const combo = p.combo[(t - 1) * N + i];
      if (combo < 0) note = `tick ${t}: no tree ran (battery flat)`;
      else {
        const tr = g.traces[String(combo)];
        acting = tr[0];
        for (const [slot, st] of tr[1]) seen.set(slot, st);
        note = acting >= 0 ? `tick ${t}: <b>${esc(g.tree.find((l) => l[1] === acting)[0].trim())}</b> acted (${STATUS[seen.get(acting)]})`
                           : `tick ${t}: no action ran (root ${STATUS[seen.get(-1)]})`;
      }
    }
    h += `<h3 style="margin-top:8px">Behavior tree <span class="muted" data-testid="acting">${note}</span></h3><pre class="tree" data-testid="tree">`;
    for (const [text, slot] of g.tree) {
      const cls = [];
      if (seen.has(slot)) cls.push("st-" + seen.get(slot)); else if (t > 0) cls.push("unvisited");
      if (slot === acting && acting >= 0) cls.push("acting");
      h += `<span class="${cls.join(" ")}" data-slot="${esc(slot)}">${esc(text)}</span>`;
    }
    return h + "</pre>";
  }

  // ------------------------------------------------------------------ state and controls
  const state = {t: 0, playing: false, speed: 2, sel: null, acc: 0, last: 0, credKey: null};
  let D = null;

  function render() {
    const t = state.t;
    $("scrub").value = String(t);
    $("tick").textContent = `tick ${t} / ${D.ticks}`;
    for (const name of PANELS) {
      draw(D, name, t);
      $("live-" + name).innerHTML = liveText(D, name, t);
    }
    $("inspector").innerHTML = inspectorHtml(D, t);
    // the tables change only at a tick with a credit: redrawn then (a swarm's table is long)
    const key = PANELS.map((n) => D.panels[n].cred.filter((c) => c[0] <= t).length).join(",");
    if (key !== state.credKey || !$("credits").firstChild) { $("credits").innerHTML = creditsHtml(D, t); state.credKey = key; }
    else $("credits").querySelector('[data-testid="credits-tick"]').textContent = String(t);
    document.body.dataset.tick = String(t);
  }

  function setTick(t) {
    state.t = Math.max(0, Math.min(D.ticks, Math.round(t)));
    render();
  }

  function setPlaying(on) {
    state.playing = on;
    $("play").innerHTML = on ? "&#10073;&#10073; Pause" : "&#9654; Play";
    if (on) {
      if (state.t >= D.ticks) setTick(0);
      state.last = performance.now(); state.acc = 0;
      requestAnimationFrame(frame);
    }
  }

  function frame(now) {
    if (!state.playing) return;
    const ticksPerSecond = state.speed / D.dt;   // 1x: real time
    state.acc += (now - state.last) / 1000 * ticksPerSecond;
    state.last = now;
    const n = Math.floor(state.acc);
    if (n > 0) {
      state.acc -= n;
      setTick(state.t + n);
      if (state.t >= D.ticks) { setPlaying(false); return; }
    }
    requestAnimationFrame(frame);
  }

  function robotAt(name, clientX, clientY) {
    const v = view[name], rect = v.canvas.getBoundingClientRect();
    const k = v.canvas.width / rect.width;
    const x = (clientX - rect.left) * k, y = (clientY - rect.top) * k;
    const p = D.panels[name], N = D.robots, t = state.t;
    let best = -1, bestD = Infinity;
    for (let i = 0; i < N; i++) {
      if (p.robots.design[i] < 0) continue;
      const [rx, ry] = toPx(v, p.posA[(t * N + i) * 2], p.posA[(t * N + i) * 2 + 1], D);
      const r = Math.max(MIN_R * v.dpr, p.robots.radius[i] * v.s) + 4 * v.dpr;
      const dd = Math.hypot(rx - x, ry - y);
      if (dd <= r && dd < bestD) { best = i; bestD = dd; }
    }
    return best;
  }

  function packageAt(name, clientX, clientY) {
    const v = view[name], rect = v.canvas.getBoundingClientRect();
    const k = v.canvas.width / rect.width;
    const x = (clientX - rect.left) * k, y = (clientY - rect.top) * k;
    const p = D.panels[name], Q = D.Q, t = state.t, pk = D.packages;
    for (let q = 0; q < Q; q++) {
      if (!pk.present[q] || p.p_status[t * Q + q] === DELIVERED) continue;
      const [px, py] = toPx(v, p.pposA[(t * Q + q) * 2], p.pposA[(t * Q + q) * 2 + 1], D);
      if (Math.hypot(px - x, py - y) <= Math.max(pk.size[q] * 1.1 * v.s, 4 * v.dpr)) return q;
    }
    return -1;
  }

  function packageText(name, q) {
    const p = D.panels[name], Q = D.Q, G = D.G, t = state.t, pk = D.packages;
    let grips = 0, held = 0;
    for (let g = 0; g < G; g++) {
      if (pk.g_eff[q * G + g] < 0) continue;
      grips++;
      if (p.holder[(t * Q + q) * G + g] >= 0) held++;
    }
    const where = p.p_status[t * Q + q] === DELIVERED ? "delivered"
      : held === 0 ? "on the ground" : held === grips ? "carried" : `${held} of ${grips} grips held, waiting`;
    return `package #${q} · class ${pk.cls[q]}: ${D.classes[pk.cls[q]] || "?"} · ${fmt(pk.mass[q], 1)} kg · ${where}` +
           (p.p_picked[t * Q + q] ? " · picked" : "");
  }

  function screenPos(name, i) {   // where robot i of a panel is on the screen now (tests, tools)
    const v = view[name], rect = v.canvas.getBoundingClientRect(), k = rect.width / v.canvas.width;
    const p = D.panels[name], N = D.robots, t = state.t;
    const [x, y] = toPx(v, p.posA[(t * N + i) * 2], p.posA[(t * N + i) * 2 + 1], D);
    return {x: rect.left + x * k, y: rect.top + y * k, cx: x * k, cy: y * k};
  }

  function showTip(tip, text, e) {   // beside the pointer, inside the window
    tip.textContent = text;
    tip.hidden = false;
    const w = tip.offsetWidth, h = tip.offsetHeight;
    const x = e.clientX + 12 + w > window.innerWidth ? Math.max(0, e.clientX - 12 - w) : e.clientX + 12;
    const y = e.clientY + 12 + h > window.innerHeight ? Math.max(0, e.clientY - 12 - h) : e.clientY + 12;
    tip.style.left = x + "px"; tip.style.top = y + "px";
  }

  function wire() {
    $("play").addEventListener("click", () => setPlaying(!state.playing));
    $("back").addEventListener("click", () => { setPlaying(false); setTick(state.t - 1); });
    $("fwd").addEventListener("click", () => { setPlaying(false); setTick(state.t + 1); });
    $("scrub").addEventListener("input", (e) => setTick(Number(e.target.value)));
    $("speed").addEventListener("change", (e) => { state.speed = Number(e.target.value); });
    document.addEventListener("keydown", (e) => {
      if (e.target && (e.target.tagName === "SELECT" || e.target.tagName === "INPUT" && e.target.type !== "range")) return;
      if (e.key === " ") { e.preventDefault(); setPlaying(!state.playing); }
      else if (e.key === "ArrowRight" && e.target.id !== "scrub") { setPlaying(false); setTick(state.t + 1); }
      else if (e.key === "ArrowLeft" && e.target.id !== "scrub") { setPlaying(false); setTick(state.t - 1); }
      else if (e.key === "Home" && e.target.id !== "scrub") { setPlaying(false); setTick(0); }
      else if (e.key === "End" && e.target.id !== "scrub") { setPlaying(false); setTick(D.ticks); }
    });
    const tip = $("tooltip");
    for (const name of PANELS) {
      const cv = $("canvas-" + name);
      cv.addEventListener("click", (e) => {
        const i = robotAt(name, e.clientX, e.clientY);
        state.sel = i >= 0 ? {panel: name, robot: i} : null;
        render();
      });
      cv.addEventListener("mousemove", (e) => {
        const i = robotAt(name, e.clientX, e.clientY);
        cv.style.cursor = i >= 0 ? "pointer" : "crosshair";
        if (i < 0) {
          const q = packageAt(name, e.clientX, e.clientY);
          if (q < 0) { tip.hidden = true; return; }
          showTip(tip, packageText(name, q), e);
          return;
        }
        const p = D.panels[name], N = D.robots, t = state.t;
        const hold = p.holding[t * N + i];
        showTip(tip, `robot ${i}: ${designLabel(D, p.robots.design[i])} · ${fmt(p.energyA[t * N + i], 0)}% energy` +
                     (hold >= 0 ? ` · holds package #${hold}` : "") + " · click for its tree", e);
      });
      cv.addEventListener("mouseleave", () => { tip.hidden = true; });
    }
    let pending = false;
    window.addEventListener("resize", () => {
      if (pending) return;
      pending = true;
      requestAnimationFrame(() => { pending = false; resize(D); render(); });
    });
  }

  async function main() {
    try {
      D = await loadData();
    } catch (err) {
      fail("The episode data could not be read: " + err.message);
      return;
    }
    prepare(D);
    const rec = D.record || {};
    $("subtitle").textContent = `${D.scenario} · ${D.robots} robots · ${D.ticks} ticks (${fmt(D.ticks * D.dt, 0)} s) · ` +
      `environment seed ${D.seed}` + (rec.generation !== undefined ? ` · best team of generation ${rec.generation}` : " · the run's best team");
    $("score-focal").textContent = `score ${fmtS(D.panels.focal.score)}`;
    $("score-baseline").textContent = `score ${fmtS(D.panels.baseline.score)}`;
    $("summary").innerHTML = summaryHtml(D);
    $("divergence").innerHTML = divergeHtml(D);
    if ($("goto-divergence")) $("goto-divergence").addEventListener("click", () => { setPlaying(false); setTick(D.divergence.tick); });
    $("legend").innerHTML = legendHtml(D);
    $("terms").innerHTML = termsHtml(D);
    $("footer").textContent = "Written by swarmcode-torch replay --html. The baseline team: the focal design's slots " +
      (!D.panels.baseline.robots.design.some((d) => d >= 0) ? "left empty: the team has no partner. "
       : D.baseline_recorded ? "refilled by its partners as the run recorded them. "
       : "refilled by the team's other designs in proportion to their dominance (app/replay_page.py). ") +
      `Both teams ran through the same environment with the evaluation's rollout (the ${D.panels.focal.tick_mode || "Python"} tick).`;
    $("scrub").max = String(D.ticks);
    resize(D);
    wire();
    render();
    window.replay = {data: D, setTick, get tick() { return state.t; }, play: () => setPlaying(true),
                     pause: () => setPlaying(false), screenPos, select: (panel, robot) => { state.sel = {panel, robot}; render(); }};
    document.body.dataset.ready = "1";
  }

  main();
})();
