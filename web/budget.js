// SPDX-License-Identifier: GPL-3.0-or-later
// The energy budget of a forced flow (the Kolmogorov flow, SPEC §6.3): what the forcing injects,
// where it goes (the film's friction, the resolved viscous dissipation and the rest, which the
// implicit sub-filter model and the scheme's numerics dissipate) and u_rms, against the
// thin-film experiment the thesis compares with (Rivera & Wu 2000).

import { formatNumber } from './charts.js';

// The experiment's budget in m²/s³ (SPEC §6.3: ε_inj = 140 ± 40, ε_film = 85 ± 35,
// ε_v = 55 ± 5 cm²/s³) and its ⟨u_rms⟩ = 0.11 ± 0.01 m/s, for the thesis' box of 42 mm.
export const EXPERIMENT = { injection: 0.014, film: 0.0085, viscous: 0.0055, urms: 0.11, box: 0.042 };
// SPEC §6.3: statistics over t ∈ [5, 20] s, once the flow is statistically steady.
const STATISTICS_FROM = 5;

/** Whether the run's samples carry the forcing's columns (a forced flow). */
export function isForced(samples) {
  return samples.some((s) => Number.isFinite(s.energy_injection));
}

/** The sample nearest in time to t (samples ordered by time). */
function nearest(samples, t) {
  let lo = 0;
  let hi = samples.length - 1;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (samples[mid].time < t) lo = mid + 1;
    else hi = mid;
  }
  if (lo > 0 && Math.abs(samples[lo - 1].time - t) < Math.abs(samples[lo].time - t)) lo -= 1;
  return samples[lo];
}

/**
 * The budget at the analysis times, where ν⟨ω²⟩ is known: (4.3) with the energy's change,
 * de_v/dt = ε_inj − ε_film − ε_v − ε_rest, so ε_rest = ε_inj − ε_film − ε_v − de_v/dt (the
 * samples' `dissipation` is −de_v/dt).
 */
export function budgetPoints(samples, analysis) {
  const points = [];
  if (!samples.length) return points;
  for (const a of analysis) {
    if (!Number.isFinite(a.vorticity)) continue;
    const s = nearest(samples, a.time);
    if (!Number.isFinite(s.energy_injection) || !Number.isFinite(s.film_dissipation)) continue;
    const rest = Number.isFinite(s.dissipation)
      ? s.energy_injection - s.film_dissipation - a.vorticity + s.dissipation : null;
    points.push({ time: a.time, viscous: a.vorticity, rest });
  }
  return points;
}

function mean(values) {
  const v = values.filter(Number.isFinite);
  return v.length ? v.reduce((sum, x) => sum + x, 0) / v.length : null;
}

/**
 * Time averages over the statistics window (t ≥ 5 s; the latter half of the run before that):
 * {from, to, injection, film, viscous, rest, urms}, or null without samples.
 */
export function budgetAverages(samples, points) {
  if (!samples.length) return null;
  const to = samples[samples.length - 1].time;
  const from = to > STATISTICS_FROM ? STATISTICS_FROM : to / 2;
  const inWindow = (t) => t >= from && t <= to;
  const s = samples.filter((x) => inWindow(x.time));
  const p = points.filter((x) => inWindow(x.time));
  return {
    from, to,
    injection: mean(s.map((x) => x.energy_injection)),
    film: mean(s.map((x) => x.film_dissipation)),
    viscous: mean(p.map((x) => x.viscous)),
    rest: mean(p.map((x) => x.rest)),
    urms: mean(s.map((x) => x.u_rms)),
  };
}

/** The caption: the averages, and the experiment's values when the box is the thesis' one. */
export function budgetCaption(averages, boxLength) {
  if (!averages) return 'no samples yet';
  const f = formatNumber;
  let text = `mean over t ∈ [${f(averages.from)}, ${f(averages.to)}] s: injection ${f(averages.injection)}, ` +
    `film ${f(averages.film)}, viscous ${f(averages.viscous)}, rest ${f(averages.rest)} m²/s³; ` +
    `u_rms ${f(averages.urms)} m/s`;
  if (Math.abs((boxLength ?? 0) - EXPERIMENT.box) < 1e-9)
    text += `. Experiment (Rivera & Wu 2000): ${f(EXPERIMENT.injection)}, ${f(EXPERIMENT.film)}, ` +
      `${f(EXPERIMENT.viscous)} m²/s³; u_rms ${f(EXPERIMENT.urms)} m/s`;
  return text;
}
