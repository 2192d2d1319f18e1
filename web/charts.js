// SPDX-License-Identifier: GPL-3.0-or-later
// Plots of the dashboard, drawn with uPlot (vendored into vendor/ by the build, a global from
// uPlot.iife.min.js) and two small canvas histograms for the chapter-4 statistics.

const MAX_POINTS = 4000;  // per series and redraw; longer histories are thinned evenly
const COLOURS = ['#1f5fa8', '#d2691e', '#2e8b57', '#8b3a8b', '#777777'];

export function plottingAvailable() {
  return typeof window.uPlot === 'function';
}

/** Short numbers for axis ticks: 0.25, 1.5e-3, 2e+4. */
export function formatNumber(v) {
  if (v === null || v === undefined || !Number.isFinite(v)) return '–';
  const a = Math.abs(v);
  if (a === 0) return '0';
  if (a >= 1e4 || a < 1e-3) return v.toExponential(2).replace('e+', 'e');
  return Number(v.toPrecision(3)).toString();
}

/** Tick labels; uPlot passes null for the unlabelled minor ticks of a log axis. */
function tickValues(u, splits) {
  return splits.map((v) => (v === null || v === undefined ? '' : formatTick(v)));
}

function formatTick(v) {
  const a = Math.abs(v);
  if (a !== 0 && (a >= 1e4 || a < 1e-3)) {
    const [mantissa, exponent] = v.toExponential(1).split('e');
    const m = Number(mantissa);
    return `${Number.isInteger(m) ? m : mantissa}e${Number(exponent)}`;
  }
  return formatNumber(v);
}

/** Indices of at most max points spread evenly over n, always keeping the last one. */
function thin(n, max) {
  if (n <= max) return null;
  const stride = n / max;
  const idx = [];
  for (let i = 0; i < max - 1; i++) idx.push(Math.floor(i * stride));
  idx.push(n - 1);
  return idx;
}

function positiveOrNull(v) {
  return Number.isFinite(v) && v > 0 ? v : null;
}

function finiteOrNull(v) {
  return Number.isFinite(v) ? v : null;
}

// Colours of the runs compared with the selected one (after its own series' colours).
const COMPARE_COLOURS = ['#8c564b', '#e377c2', '#17becf', '#bcbd22', '#7f7f7f', '#9467bd'];

class Chart {
  /**
   * container: element the plot goes into; opts: {xLabel, yLabel, series: [{label, points,
   * dash}], logX, logY, height, markers: () => [{x, label}], draw: extra draw hook}
   */
  constructor(container, opts) {
    this.container = container;
    this.opts = opts;
    this.markers = [];
    this.count = 0;
    const height = opts.height ?? 220;
    const series = [{ label: opts.xLabel }];
    opts.series.forEach((s, i) => {
      series.push({
        label: s.label,
        stroke: s.stroke ?? COLOURS[i % COLOURS.length],
        width: s.width ?? 1.5,
        dash: s.dash,
        spanGaps: true,
        points: { show: s.points ?? false, size: 5 },
        value: (u, v) => formatNumber(v),
      });
    });
    const log = (on) => (on ? { distr: 3, log: 10 } : {});
    this.plot = new window.uPlot(
      {
        width: Math.max(200, container.clientWidth || 400),
        height,
        scales: { x: { time: false, ...log(opts.logX) }, y: log(opts.logY) },
        axes: [
          { label: opts.xLabel, values: tickValues, labelSize: 20, labelGap: 0 },
          { label: opts.yLabel, values: tickValues, size: 60, labelSize: 20, labelGap: 0 },
        ],
        series,
        legend: { live: true },
        hooks: { draw: [(u) => this.drawMarkers(u)] },
      },
      [[], ...opts.series.map(() => [])],
      container,
    );
    this.resizeObserver = new ResizeObserver(() => {
      const width = Math.max(200, container.clientWidth);
      if (width !== this.plot.width) this.plot.setSize({ width, height });
    });
    this.resizeObserver.observe(container);
  }

  /**
   * Extra series after the chart's own, one per label (runs compared with the selected one):
   * added or removed to match, in the comparison palette.
   */
  setExtraSeries(labels) {
    const own = this.opts.series.length;
    while (this.plot.series.length - 1 > own + labels.length) this.plot.delSeries(this.plot.series.length - 1);
    labels.forEach((label, i) => {
      const at = own + 1 + i;
      if (at < this.plot.series.length) {
        if (this.plot.series[at].label === label) return;
        this.plot.delSeries(at);
      }
      this.plot.addSeries({
        label,
        stroke: COMPARE_COLOURS[i % COMPARE_COLOURS.length],
        width: 1.5,
        spanGaps: true,
        points: { show: false },
        value: (u, v) => formatNumber(v),
      }, at);
    });
  }

  /** x: numbers; ys: one array per series (null = gap). */
  setData(x, ys) {
    const idx = thin(x.length, MAX_POINTS);
    const pick = (a) => (idx ? idx.map((i) => a[i]) : a);
    const clean = this.opts.logY ? positiveOrNull : finiteOrNull;
    const cleanX = this.opts.logX ? positiveOrNull : finiteOrNull;
    const xs = pick(x).map(cleanX);
    const data = [xs, ...ys.map((a) => pick(a).map(clean))];
    // A log axis needs at least one positive value to place its ticks.
    const drawable = data.slice(1).some((a) => a.some((v) => v !== null));
    this.count = x.length;
    // Points of the first series (the run's own; a reference curve may share the x axis).
    this.container.dataset.points = String(drawable ? ys[0].filter((v) => v !== null && v !== undefined).length : 0);
    // Points of the extra (compared) series, for the browser test.
    const extra = ys.slice(this.opts.series.length);
    this.container.dataset.comparePoints = String(extra.reduce(
      (n, a) => n + a.filter((v) => v !== null && v !== undefined).length, 0));
    this.plot.setData(drawable ? data : [[], ...ys.map(() => [])]);
  }

  setMarkers(markers) {
    this.markers = markers;
    this.plot.redraw(false, false);
  }

  drawMarkers(u) {
    if (!this.markers.length || !u.data[0].length) return;
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    const dpr = window.devicePixelRatio || 1;
    ctx.save();
    ctx.font = `${11 * dpr}px system-ui, sans-serif`;
    ctx.textBaseline = 'top';
    for (const m of this.markers) {
      if (!(m.x > 0)) continue;
      const x = u.valToPos(m.x, 'x', true);
      if (x < left || x > left + width) continue;
      ctx.strokeStyle = m.colour;
      ctx.fillStyle = m.colour;
      ctx.lineWidth = dpr;
      ctx.setLineDash([4 * dpr, 3 * dpr]);
      ctx.beginPath();
      ctx.moveTo(x, top);
      ctx.lineTo(x, top + height);
      ctx.stroke();
      const text = m.label;
      const w = ctx.measureText(text).width;
      const tx = x + 3 * dpr + w > left + width ? x - 3 * dpr - w : x + 3 * dpr;
      ctx.fillText(text, tx, top + 3 * dpr + (m.row ?? 0) * 13 * dpr);
    }
    ctx.restore();
  }

  destroy() {
    this.resizeObserver.disconnect();
    this.plot.destroy();
  }
}

export function energyChart(container) {
  return new Chart(container, {
    xLabel: 't [s]',
    yLabel: 'eᵥ [m²/s²]',
    series: [
      { label: 'eᵥ (particles)' },
      { label: 'reference', stroke: '#555555', dash: [6, 4], width: 1.5 },
      // SPEC §9: the energy of the shells k ≤ k_SPH, the run's and its reference run's.
      { label: 'E_res (k ≤ k_SPH)', points: true, width: 1 },
      { label: 'E_res reference', stroke: '#000000', dash: [3, 3], width: 1.5 },
    ],
  });
}

export function dissipationChart(container) {
  return new Chart(container, {
    xLabel: 't [s]',
    yLabel: 'ε [m²/s³]',
    series: [
      { label: '−deᵥ/dt' },
      { label: '2ν∫k²E dk (spectral)', points: true, width: 1 },
      { label: 'ν⟨ω²⟩ (vorticity)', points: true, width: 1 },
      { label: 'reference', stroke: '#555555', dash: [6, 4], width: 1.5 },
    ],
  });
}

/** The budget of a forced flow (budget.js): per-step injection and film friction, the
 *  analysis times' viscous dissipation and the rest (sub-filter and numerical). */
export function budgetChart(container) {
  return new Chart(container, {
    xLabel: 't [s]',
    yLabel: 'ε [m²/s³]',
    series: [
      { label: 'injection ⟨χ sin(k_y y) vₓ⟩' },
      { label: 'film μ⟨|v|²⟩' },
      { label: 'viscous ν⟨ω²⟩', points: true, width: 1 },
      { label: 'rest: sub-filter and numerical', points: true, width: 1 },
      { label: 'deᵥ/dt', stroke: '#999999', width: 1 },
    ],
  });
}

export function rmsChart(container) {
  return new Chart(container, {
    xLabel: 't [s]',
    yLabel: 'u_rms [m/s]',
    series: [
      { label: 'u_rms' },
      { label: 'experiment 0.11 m/s', stroke: '#555555', dash: [6, 4], width: 1.5 },
    ],
  });
}

export function spectrumChart(container) {
  return new Chart(container, {
    xLabel: 'k [1/m]',
    yLabel: 'E(k) [m³/s²]',
    logX: true,
    logY: true,
    height: 260,
    series: [
      { label: 'E(k)', points: true, width: 1.5 },
      { label: 'k^(−5/3)', stroke: '#999999', dash: [6, 4], width: 1 },
      { label: 'reference E(k)', stroke: '#000000', dash: [3, 3], width: 1.5 },
    ],
  });
}

export function statisticsChart(container) {
  return new Chart(container, {
    xLabel: 't [s]',
    yLabel: '|τ_SFS| [Pa]',
    logY: true,
    series: [
      { label: 'max |τ_SFS|', points: true },
      { label: 'mean |τ_SFS|', points: true },
    ],
  });
}

/**
 * E(k) with a k^(−5/3) guide through the spectrum's peak, over the wavenumbers above it.
 * Returns the chart data {x, ys}.
 */
export function spectrumData(k, energy) {
  const x = [];
  const e = [];
  for (let i = 0; i < k.length; i++) {
    if (k[i] > 0) {
      x.push(k[i]);
      e.push(energy[i] > 0 ? energy[i] : null);
    }
  }
  let peak = -1;
  for (let i = 0; i < e.length; i++) if (e[i] !== null && (peak < 0 || e[i] > e[peak])) peak = i;
  const guide = x.map((kk, i) =>
    peak >= 0 && i >= peak ? e[peak] * (kk / x[peak]) ** (-5 / 3) : null);
  return { x, ys: [e, guide] };
}

// Sequential colour map for the histograms (viridis, 6 stops interpolated).
const VIRIDIS = [
  [68, 1, 84], [65, 68, 135], [42, 120, 142], [34, 168, 132], [122, 209, 81], [253, 231, 37],
];

function viridis(f) {
  const x = Math.min(1, Math.max(0, f)) * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(x));
  const t = x - i;
  const c = VIRIDIS[i].map((a, j) => Math.round(a + t * (VIRIDIS[i + 1][j] - a)));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}

function prepareCanvas(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || 300;
  const h = canvas.clientHeight || 220;
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  ctx.font = '11px system-ui, sans-serif';
  ctx.fillStyle = '#333';
  ctx.strokeStyle = '#333';
  return { ctx, w, h };
}

/**
 * Bivariate histogram of (τ*, ω²*) = (|τ_SFS|/max, ω²/max), counts[bx + bins_x * by], on a
 * log colour scale. joint: {bins_x, bins_y, counts, total}.
 */
export function drawJointHistogram(canvas, joint) {
  const { ctx, w, h } = prepareCanvas(canvas);
  const pad = { l: 42, r: 74, t: 8, b: 34 };  // the colour legend on the right
  const pw = w - pad.l - pad.r;
  const ph = h - pad.t - pad.b;
  const nx = joint?.bins_x | 0;
  const ny = joint?.bins_y | 0;
  const counts = Array.isArray(joint?.counts) ? joint.counts : [];
  canvas.dataset.cells = String(nx > 0 && ny > 0 && counts.length === nx * ny ? counts.length : 0);
  canvas.dataset.legendMax = '0';
  if (nx > 0 && ny > 0 && counts.length === nx * ny) {
    const maxCount = Math.max(...counts);
    const maxLog = Math.log10(1 + maxCount);
    drawCountLegend(ctx, pad.l + pw + 14, pad.t, ph, maxCount);
    canvas.dataset.legendMax = String(maxCount);
    for (let by = 0; by < ny; by++) {
      for (let bx = 0; bx < nx; bx++) {
        const c = counts[bx + nx * by];
        if (!c) continue;
        ctx.fillStyle = viridis(maxLog > 0 ? Math.log10(1 + c) / maxLog : 0);
        const x0 = pad.l + (bx / nx) * pw;
        const y0 = pad.t + ph - ((by + 1) / ny) * ph;
        ctx.fillRect(x0, y0, pw / nx + 0.5, ph / ny + 0.5);
      }
    }
  } else {
    ctx.fillText('no histogram yet', pad.l + 8, pad.t + 16);
  }
  ctx.fillStyle = '#333';
  ctx.strokeRect(pad.l, pad.t, pw, ph);
  ctx.textAlign = 'center';
  ctx.fillText('0', pad.l, pad.t + ph + 12);
  ctx.fillText('1', pad.l + pw, pad.t + ph + 12);
  ctx.fillText('τ* = |τ_SFS| / max [–]', pad.l + pw / 2, pad.t + ph + 26);
  ctx.textAlign = 'right';
  ctx.fillText('1', pad.l - 4, pad.t + 8);
  ctx.fillText('0', pad.l - 4, pad.t + ph);
  ctx.save();
  ctx.translate(12, pad.t + ph / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = 'center';
  ctx.fillText('ω²* = ω² / max [–]', 0, 0);
  ctx.restore();
}

/** The joint histogram's colour scale: particles per cell, log(1 + count), with decade ticks. */
function drawCountLegend(ctx, x, top, height, maxCount) {
  const barWidth = 12;
  const maxLog = Math.log10(1 + maxCount);
  const steps = 64;
  for (let i = 0; i < steps; i++) {
    ctx.fillStyle = viridis((i + 0.5) / steps);
    ctx.fillRect(x, top + height - ((i + 1) / steps) * height, barWidth, height / steps + 0.5);
  }
  ctx.strokeStyle = '#333';
  ctx.strokeRect(x, top, barWidth, height);
  ctx.fillStyle = '#333';
  ctx.textAlign = 'left';
  const at = (count) => top + height - (maxLog > 0 ? Math.log10(1 + count) / maxLog : 0) * height;
  // From the top (the largest count, always labelled) down: a label too close to the one above
  // it is left out, so that none overlap.
  const ticks = [maxCount];
  for (let d = 10 ** Math.floor(Math.log10(Math.max(1, maxCount))); d >= 1; d /= 10)
    if (d < maxCount) ticks.push(d);
  if (maxCount > 0) ticks.push(0);
  let lastY = -Infinity;
  for (const c of ticks) {
    const y = at(c);
    if (y - lastY < 11) continue;
    ctx.fillRect(x + barWidth, y - 0.5, 3, 1);
    ctx.fillText(String(c), x + barWidth + 5, Math.min(top + height, Math.max(top + 8, y + 4)));
    lastY = y;
  }
  ctx.save();
  ctx.translate(x + barWidth + 38, top + height / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = 'center';
  ctx.fillText('particles per cell', 0, 0);
  ctx.restore();
}

/**
 * Polar-angle histogram of γ ∈ [0°, 90°] between t_I and v (2D runs), as bars of the fraction
 * of particles. alignment: {bins, threshold, counts, total}.
 */
export function drawAlignmentHistogram(canvas, alignment) {
  const { ctx, w, h } = prepareCanvas(canvas);
  const pad = { l: 42, r: 10, t: 8, b: 34 };
  const pw = w - pad.l - pad.r;
  const ph = h - pad.t - pad.b;
  const counts = Array.isArray(alignment?.counts) ? alignment.counts : [];
  const total = counts.reduce((a, b) => a + b, 0);
  if (counts.length && total > 0) {
    const fractions = counts.map((c) => c / total);
    const top = Math.max(...fractions);
    ctx.fillStyle = '#1f5fa8';
    fractions.forEach((f, i) => {
      const bh = (f / top) * ph;
      ctx.fillRect(pad.l + (i / counts.length) * pw + 1, pad.t + ph - bh, pw / counts.length - 2, bh);
    });
    ctx.fillStyle = '#333';
    ctx.textAlign = 'right';
    ctx.fillText(formatNumber(top), pad.l - 4, pad.t + 8);
  } else {
    ctx.fillText(alignment ? 'no particles above the threshold' : 'not computed (3D run)',
      pad.l + 8, pad.t + 16);
  }
  ctx.fillStyle = '#333';
  ctx.strokeRect(pad.l, pad.t, pw, ph);
  ctx.textAlign = 'right';
  ctx.fillText('0', pad.l - 4, pad.t + ph);
  ctx.textAlign = 'center';
  ctx.fillText('0°', pad.l, pad.t + ph + 12);
  ctx.fillText('90°', pad.l + pw, pad.t + ph + 12);
  ctx.fillText('γ between t_I and v [°]', pad.l + pw / 2, pad.t + ph + 26);
  ctx.save();
  ctx.translate(12, pad.t + ph / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.fillText('fraction [–]', 0, 0);
  ctx.restore();
}
