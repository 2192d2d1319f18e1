// SPDX-License-Identifier: GPL-3.0-or-later
// Browser end-to-end test of the sphles dashboard (ctest: web_e2e, label e2e).
//
// Starts the real server (`sphles serve --port 0` on loopback, a fresh data directory), opens the
// dashboard in Debian's chromium (headless, driven by playwright-core), creates a small 2D
// Taylor-Green run from the form, and checks what a person would see: the e_v plot gets data, the
// ω² slice image updates (two decoded images of different steps), pause stops the step count,
// resume advances it again, stop ends the run, delete removes it; and the page logs no console
// error.
//
//   node tests/e2e/dashboard.test.mjs --sphles build/app/sphles --web web \
//        [--chromium /usr/bin/chromium] [--screenshot /tmp/dashboard.png]
// Environment instead of flags: SPHLES_BINARY, SPHLES_WEB, SPHLES_CHROMIUM, SPHLES_SCREENSHOT.
// Exit 0 when every check passes, 1 with the failed check and the server's output otherwise.

import { spawn } from 'node:child_process';
import { existsSync, mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { createRequire } from 'node:module';

const DEADLINE_MS = 90_000;
const PARTICLES_PER_SIDE = 24;  // 24² particles: hundreds of steps per second on one core
const END_TIME = 500;           // [s] far beyond what the test runs: the run cannot finish early
const ANALYSIS_EVERY = 0.05;    // [s] simulated time between analysis frames (and images)

const started = Date.now();
const elapsed = () => `${((Date.now() - started) / 1000).toFixed(1)} s`;
const log = (text) => console.log(`[web_e2e ${elapsed()}] ${text}`);

function option(name, envName, fallback) {
  const i = process.argv.indexOf(`--${name}`);
  if (i >= 0 && i + 1 < process.argv.length) return process.argv[i + 1];
  return process.env[envName] ?? fallback;
}

const sphles = option('sphles', 'SPHLES_BINARY');
const webDir = option('web', 'SPHLES_WEB');
const chromiumPath = option('chromium', 'SPHLES_CHROMIUM', '/usr/bin/chromium');
const screenshot = option('screenshot', 'SPHLES_SCREENSHOT');

class CheckFailed extends Error {}

let page = null;
let server = null;
let serverOutput = '';
let browser = null;
let dataDir = null;
let currentStep = 'setting up';
const consoleErrors = [];
const checks = [];

function fail(message) {
  throw new CheckFailed(message);
}

function pass(name) {
  checks.push(name);
  log(`ok: ${name}`);
}

function preflight() {
  const missing = [];
  if (!sphles || !existsSync(sphles)) missing.push(`sphles binary (--sphles, got ${sphles ?? 'nothing'})`);
  if (!webDir || !existsSync(join(webDir, 'index.html'))) missing.push(`web directory with index.html (--web, got ${webDir ?? 'nothing'})`);
  else if (!existsSync(join(webDir, 'vendor', 'uPlot.iife.min.js')))
    missing.push(`${join(webDir, 'vendor', 'uPlot.iife.min.js')} (build the CMake target web_assets)`);
  if (!existsSync(chromiumPath)) missing.push(`chromium at ${chromiumPath} (scripts/setup.sh installs Debian's chromium)`);
  if (missing.length) fail(`missing: ${missing.join('; ')}`);
}

function loadPlaywright() {
  const require = createRequire(import.meta.url);
  try {
    return require('playwright-core');
  } catch {
    fail('playwright-core is not installed in tests/e2e/node_modules: build the CMake target ' +
      'e2e_node_modules or run `npm ci` in tests/e2e');
  }
  return null;
}

/** Starts `sphles serve` and resolves with its base URL from the "listening on" line. */
function startServer() {
  dataDir = mkdtempSync(join(tmpdir(), 'sphles-e2e-'));
  // Runs with ranks > 1 start as an MPI job: mpiexec, oversubscribed on CI's 2 cores (and as
  // root in CI's containers, which OpenMPI refuses unless told).
  const args = ['serve', '--port', '0', '--data', join(dataDir, 'data'), '--web', resolve(webDir),
    '--launcher', 'mpiexec --oversubscribe --bind-to none -n {ranks}'];
  log(`starting ${sphles} ${args.join(' ')}`);
  server = spawn(sphles, args, {
    stdio: ['ignore', 'pipe', 'pipe'],
    env: {
      ...process.env, XDG_CACHE_HOME: join(dataDir, 'cache'), OMPI_ALLOW_RUN_AS_ROOT: '1',
      OMPI_ALLOW_RUN_AS_ROOT_CONFIRM: '1', OMPI_MCA_mpi_yield_when_idle: '1',
    },
  });
  return new Promise((resolvePromise, reject) => {
    const timer = setTimeout(() => reject(new CheckFailed('the server printed no "listening on" line within 20 s')), 20_000);
    let buffer = '';
    server.stdout.on('data', (chunk) => {
      const text = chunk.toString();
      serverOutput += text;
      buffer += text;
      const m = buffer.match(/sphles serve: listening on (http:\/\/\S+?)\/?\s/);
      if (m) {
        clearTimeout(timer);
        resolvePromise(`${m[1]}/`);
      }
    });
    server.stderr.on('data', (chunk) => { serverOutput += chunk.toString(); });
    server.on('exit', (code, signal) => {
      clearTimeout(timer);
      reject(new CheckFailed(`the server exited early (code ${code}, signal ${signal})`));
    });
  });
}

async function stopServer() {
  if (!server || server.exitCode !== null) return;
  const exited = new Promise((r) => server.once('exit', r));
  server.kill('SIGTERM');
  const timer = setTimeout(() => server.kill('SIGKILL'), 10_000);
  await exited;
  clearTimeout(timer);
}

/** Polls fn() until it returns a truthy value; fails with `what` after timeoutMs. */
async function waitFor(what, fn, timeoutMs) {
  currentStep = what;
  const end = Date.now() + timeoutMs;
  let last;
  for (;;) {
    last = await fn();
    if (last) return last;
    if (Date.now() > end) fail(`timed out after ${timeoutMs / 1000} s waiting for: ${what}`);
    await new Promise((r) => setTimeout(r, 200));
  }
}

const text = (page, selector) => page.locator(selector).textContent();

/** A 16³ 3D Taylor-Green run of viscosity `eta` (ρ = 1: Re = 1/eta) to t = 0.5 with spectra at
 *  t = 0, 0.25 and 0.5, created through the API, finished and selected in the run list; its id.
 *  `kernel`: its scene's kernel section, if not the default. */
async function selectFinishedTgv3d(base, name, eta, kernel = undefined) {
  const created = await fetch(`${base}/api/runs`, {
    method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ scene: { case: 'tgv3d', name, particles_per_side: 16, kernel,
      fluid: { dynamic_viscosity: eta }, packing: { enabled: false }, time: { end: 0.5 },
      analysis: { every: 0.25, products: ['spectrum'] } } }),
  });
  if (created.status !== 201) fail(`creating run ${name}: HTTP ${created.status}`);
  const id = (await created.json()).id;
  await waitFor(`run ${name} to finish`, async () =>
    (await (await fetch(`${base}/api/runs/${id}`)).json()).state === 'finished', 60_000);
  const item = page.locator(`#run-list li[data-id="${id}"] button`);
  await waitFor(`run ${name} in the list`, async () => (await item.count()) === 1, 10_000);
  await item.click();
  return id;
}
const stepOf = async (page) => Number(await text(page, '#run-step'));

async function imageState(page) {
  return page.evaluate(() => {
    const img = document.getElementById('img-omega2');
    return { src: img.getAttribute('src') ?? '', step: img.dataset.step ?? '', width: img.naturalWidth, complete: img.complete };
  });
}

async function run() {
  preflight();
  const { chromium } = loadPlaywright();
  const base = await startServer();
  log(`server at ${base}`);

  currentStep = 'launching chromium';
  browser = await chromium.launch({
    executablePath: chromiumPath,
    headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  page = await browser.newPage({ viewport: { width: 1440, height: 1500 } });
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(`console: ${m.text()}`); });
  page.on('pageerror', (e) => consoleErrors.push(`uncaught: ${e.message}`));
  // Name the URL of every failed request: the console message alone does not.
  page.on('response', (r) => { if (r.status() >= 400) consoleErrors.push(`HTTP ${r.status()} ${r.request().method()} ${r.url()}`); });

  currentStep = 'opening the dashboard';
  await page.goto(base, { waitUntil: 'load' });
  await waitFor('the server connection to show "ok"', async () =>
    (await page.locator('#api-state').getAttribute('data-state')) === 'open', 10_000);
  if (await page.locator('#page-error').isVisible()) fail(`page shows an error: ${await text(page, '#page-error')}`);
  pass('dashboard loads, REST API reachable, plotting library present');

  // The run form: a 2D Taylor-Green vortex (the server's preset tgv2d).
  const labels = await waitFor('presets in the form', async () => {
    const all = await page.locator('#create-preset option').allTextContents();
    return all.length ? all : null;
  }, 10_000);
  // Every scene file of scenes/ is offered beside the presets (GET /api/scenes).
  const sceneFiles = (await (await fetch(`${base}/api/scenes`)).json()).scenes.map((s) => s.name);
  const missingScenes = sceneFiles.filter((name) => !labels.some((l) => l.startsWith(`scene: ${name} (`)));
  if (sceneFiles.length < 9 || missingScenes.length)
    fail(`the form does not offer the scene files ${missingScenes.join(', ')} (offers: ${labels.join(', ')})`);
  pass(`the form offers the ${sceneFiles.length} scene files of scenes/ beside the presets`);
  // The form's choices and bounds are the scene schema's (GET /api/schema/scene): the kernel
  // select offers exactly the schema's kernel names, and a number field its bounds.
  const schema = await (await fetch(`${base}/api/schema/scene`)).json();
  const kernelNames = schema.properties.kernel.properties.type.enum;
  await waitFor('the kernel choices of the scene schema', async () => {
    const values = await page.locator('#create-kernel option').evaluateAll((os) => os.map((o) => o.value));
    return JSON.stringify(values) === JSON.stringify(['', ...kernelNames]) ? values : null;
  }, 10_000);
  const particles = page.locator('#create-particles');
  const schemaPps = schema.properties.particles_per_side;
  if ((await particles.getAttribute('max')) !== String(schemaPps.maximum) ||
      !(await particles.getAttribute('title'))?.startsWith(schemaPps.description.slice(0, 10)))
    fail('the particles field does not carry the scene schema\'s bound and description');
  pass(`form fields follow the scene schema (${kernelNames.length} kernels, bounds, descriptions)`);
  // The same schema validates the form in the browser (ajv): a value beyond a bound is refused
  // before any request, worded as the server words it.
  const requestsBefore = (await (await fetch(`${base}/api/runs`)).json()).length;
  await page.fill('#create-particles', String(schemaPps.maximum + 1));
  await page.click('#create-estimate');
  const refusal = await waitFor('the form to refuse particles_per_side beyond its bound', async () => {
    const t = await text(page, '#create-status');
    return t.includes("'particles_per_side'") ? t : null;
  }, 5_000);
  if (!refusal.includes(`<= ${schemaPps.maximum}`)) fail(`unexpected refusal: ${refusal}`);
  if ((await (await fetch(`${base}/api/runs`)).json()).length !== requestsBefore) fail('a run was created');
  pass(`the browser validates the scene against the schema: "${refusal}"`);

  const label = labels.find((l) => /tgv2d/i.test(l));
  if (!label) fail(`no 2D Taylor-Green choice in the run form (options: ${labels.join(', ')})`);
  await page.selectOption('#create-preset', { label });
  await page.fill('#create-particles', String(PARTICLES_PER_SIDE));
  await page.fill('#create-end', String(END_TIME));
  await page.check('#create-live');
  await page.fill('#create-every', String(ANALYSIS_EVERY));
  // A scheme and its options from the form: the transport-velocity formulation with the
  // Galilean-invariant ALE form of its extra stress; checked in the run's scene below.
  await page.selectOption('#create-scheme', 'transport_velocity');
  await page.fill('#create-dk', '7');  // the kernel's D_K/Δl, offered beside η
  await page.selectOption('#create-ale', 'full');
  // The particle snapshot product, chosen beside the live ones.
  await page.check('#create-products input[data-product="particles"]');
  await page.fill('#create-name', 'e2e-tgv2d');
  await page.fill('#create-ranks', '2');  // the solver in a 2-rank MPI job (the server's --launcher)
  await page.check('#create-start');
  // The estimate before Create: memory and the time per step measured on the server.
  const runsBefore = (await (await fetch(`${base}/api/runs`)).json()).length;
  await page.click('#create-estimate');
  const perStep = await waitFor('the estimate with a time per step', async () => {
    if (await page.locator('#create-estimate-result').isHidden()) return null;
    const t = await text(page, '#create-estimate-result dd[data-field="per step"]');
    return /\d/.test(t) ? t : null;
  }, 20_000);
  const estimateStatus = await text(page, '#create-status');
  if (!/would accept/.test(estimateStatus)) fail(`the estimate says: ${estimateStatus}`);
  if ((await (await fetch(`${base}/api/runs`)).json()).length !== runsBefore) fail('the estimate created a run');
  // The run's 2 ranks: what each would hold (the API's per_rank).
  const perRank = await text(page, '#create-estimate-result dd[data-field="per rank"]');
  if (!/on each of 2 ranks \(2 × 1\)/.test(perRank)) fail(`the estimate shows no per-rank memory for 2 ranks: "${perRank}"`);
  // What admission charges this machine for them (the API's memory_here_bytes).
  const here = await text(page, '#create-estimate-result dd[data-field="this machine"]');
  if (!/ of the .* allowed \(the 2 ranks run here, beside the server's /.test(here)) fail(`the estimate does not say what this machine gives the 2 ranks: "${here}"`);
  pass(`estimate before Create: ${perStep} per step, ${await text(page, '#create-estimate-result dd[data-field="memory"]')}, per rank ${perRank}, this machine ${here}`);
  // The reference's refetches (?until=) fail at first: the page must back off (1, 2, 4 … s
  // between tries), not ask again at every redraw.
  const isRefetch = (url) => url.pathname.endsWith('/reference') && url.searchParams.has('until');
  let failedRefetches = 0;
  const failRefetch = (route) => { failedRefetches += 1; return route.fulfill({ status: 503, contentType: 'application/json', body: '{"error":{"status":503,"message":"test: unavailable"}}' }); };
  await page.route(isRefetch, failRefetch);
  await page.click('#create-submit');
  await waitFor('the new run to be selected', async () => (await text(page, '#run-title')) === 'e2e-tgv2d', 10_000);
  const createStatus = await text(page, '#create-status');
  if (/refused|error|must|unknown/i.test(createStatus)) fail(`creating the run failed: ${createStatus}`);
  await waitFor('state "running"', async () => (await text(page, '#run-state')) === 'running', 30_000);
  pass(`run created from "${label}" with ${PARTICLES_PER_SIDE}² particles and running`);

  await waitFor('the stream connection to open', async () =>
    (await page.locator('#ws-state').getAttribute('data-state')) === 'open', 10_000);
  pass('WebSocket stream open');

  const points = await waitFor('the e_v plot to get data (>= 3 samples)', async () => {
    const n = Number(await page.locator('#chart-energy').getAttribute('data-points'));
    return n >= 3 ? n : 0;
  }, 30_000);
  const morePoints = await waitFor('the e_v plot to grow', async () => {
    const n = Number(await page.locator('#chart-energy').getAttribute('data-points'));
    return n > points ? n : 0;
  }, 15_000);
  pass(`e_v plot has data and grows (${points} → ${morePoints} samples)`);
  // The reference: the 2D TGV's analytic decay, dashed under the run's e_v.
  const referencePoints = await waitFor('the analytic reference in the e_v plot', async () =>
    Number(await page.locator('#chart-energy').getAttribute('data-reference-points')), 10_000);
  if (!/analytic decay/.test(await text(page, '#cap-energy'))) fail(`the e_v caption does not name the reference: ${await text(page, '#cap-energy')}`);
  pass(`reference curve drawn with the run (${referencePoints} points of the analytic decay)`);
  await waitFor('the first refetch of the reference', async () => failedRefetches > 0, 15_000);
  await page.waitForTimeout(3_500);
  await page.unroute(isRefetch, failRefetch);
  // Tries at 0, 1 and 3 s (a 4th if the clock straddles); a page without back-off asks at
  // every redraw, dozens of times.
  if (failedRefetches > 4) fail(`the failing reference refetch was asked ${failedRefetches} times in 3.5 s`);
  for (let k = consoleErrors.length - 1; k >= 0; k--)
    if (/reference\?until=.* 503|status of 503/.test(consoleErrors[k]) || /HTTP 503 GET .*\/reference\?until=/.test(consoleErrors[k])) consoleErrors.splice(k, 1);
  pass(`a failing reference refetch backs off: ${failedRefetches} tries in 3.5 s`);
  // The reference is sampled over the plotted span (asked for again with ?until=), not a
  // handful of points ...
  const finePoints = await waitFor('the reference sampled over the plotted span', async () => {
    const n = Number(await page.locator('#chart-energy').getAttribute('data-reference-points'));
    return n >= 50 ? n : 0;
  }, 20_000);
  // ... and reaches no further than twice the run's latest time (time.end is far away).
  const referenceEnd = Number(await page.locator('#chart-energy').getAttribute('data-reference-end'));
  const latestTime = Number(await page.locator('#chart-energy').getAttribute('data-latest'));
  if (!(referenceEnd > 0 && referenceEnd <= 2 * latestTime + 1e-9)) fail(`the reference runs to t = ${referenceEnd} for a run at t = ${latestTime}`);
  pass(`the reference is drawn to t = ${referenceEnd.toPrecision(3)}, within twice the run's t = ${latestTime.toPrecision(3)}, with ${finePoints} points`);
  const eta = await waitFor('an ETA for the running run', async () => {
    const t = await text(page, '#run-eta');
    return /\d/.test(t) ? t : null;
  }, 15_000);
  pass(`ETA shown while running: ${eta}`);
  // Once it steps, the set-up's phase ("packing the initial lattice…") is no longer shown, and a
  // panel without an image yet shows its caption, not a broken-image icon.
  const phase = await waitFor('the set-up phase cleared while stepping', async () =>
    ((await text(page, '#run-phase')) === '' ? 'cleared' : null), 15_000);
  const emptyPanels = await page.evaluate(() => [...document.querySelectorAll('.images img:not([src])')]
    .filter((img) => getComputedStyle(img).visibility !== 'hidden').length);
  if (emptyPanels !== 0) fail(`${emptyPanels} image panels without an image are visible`);
  pass(`set-up phase ${phase} while stepping; empty image panels hidden`);

  // The run's log: run.log's lines, the start among them, and new lines while it runs.
  const logLines = await waitFor('the run log with its start', async () => {
    const log = await text(page, '#run-log');
    return /state: (created|queued) -> running/.test(log)
      ? Number(await page.locator('#run-log').getAttribute('data-lines')) : 0;
  }, 10_000);
  const moreLogLines = await waitFor('the run log to grow (progress lines)', async () => {
    const n = Number(await page.locator('#run-log').getAttribute('data-lines'));
    return n > logLines ? n : 0;
  }, 30_000);
  pass(`run log shown and growing (${logLines} → ${moreLogLines} lines)`);

  const first = await waitFor('a decoded ω² slice image', async () => {
    const s = await imageState(page);
    return s.complete && s.width > 0 && s.step ? s : null;
  }, 40_000);
  const second = await waitFor('a second ω² image of a later step', async () => {
    const s = await imageState(page);
    return s.complete && s.width > 0 && s.step && s.step !== first.step && s.src !== first.src ? s : null;
  }, 30_000);
  pass(`ω² image updated: step ${first.step} → ${second.step} (${second.width} px wide)`);

  // Plots show only the selected run: another run without products empties the spectrum and the
  // joint histogram; selecting this run again refills them.
  currentStep = 'switching runs';
  const productsShown = async () => ({
    spectrum: Number(await page.locator('#chart-spectrum').getAttribute('data-points')),
    joint: Number(await page.locator('#hist-joint').getAttribute('data-cells')),
  });
  await waitFor('a spectrum and a joint histogram of the running run', async () => {
    const shown = await productsShown();
    return shown.spectrum > 0 && shown.joint > 0 &&
      Number(await page.locator('#hist-joint').getAttribute('data-legend-max')) > 0;
  }, 30_000);
  const idle = await fetch(`${base}/api/runs`, {
    method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ preset: 'tgv3d', name: 'e2e-idle', start: false }),
  });
  if (idle.status !== 201) fail(`creating the idle run: HTTP ${idle.status}`);
  const idleId = (await idle.json()).id;
  const idleItem = page.locator(`#run-list li[data-id="${idleId}"] button`);
  await waitFor('the idle run in the list', async () => (await idleItem.count()) === 1, 10_000);
  await idleItem.click();
  await waitFor('the idle run selected', async () => (await text(page, '#run-title')) === 'e2e-idle', 10_000);
  await page.waitForTimeout(600);  // past the redraw delay
  const cleared = await productsShown();
  if (cleared.spectrum !== 0 || cleared.joint !== 0)
    fail(`the idle run shows the other run's products: ${JSON.stringify(cleared)}`);
  if ((await text(page, '#cap-spectrum')) !== 'no spectrum yet') fail('the spectrum caption was not reset');
  const runningItem = page.locator('#run-list li button', { hasText: 'e2e-tgv2d' });
  await runningItem.click();
  await waitFor('the running run selected again', async () => (await text(page, '#run-title')) === 'e2e-tgv2d', 10_000);
  await waitFor('its spectrum and joint histogram back', async () => {
    const shown = await productsShown();
    return shown.spectrum > 0 && shown.joint > 0;
  }, 30_000);
  pass('switching runs shows only the selected run\'s spectrum and histograms');
  // The idle run has served: without it no other "created" run can be auto-selected when the
  // test later deletes the selected one.
  const removed = await fetch(`${base}/api/runs/${idleId}`, { method: 'DELETE' });
  if (removed.status !== 204 && removed.status !== 200) fail(`deleting the idle run: HTTP ${removed.status}`);

  if (screenshot) {
    await page.waitForTimeout(1500);  // let the spectrum and statistics plots fill in
    await page.screenshot({ path: screenshot, fullPage: true });
    log(`screenshot: ${screenshot}`);
  }

  // Pause: the state shows paused and the step count stops.
  currentStep = 'pausing';
  await page.click('#btn-pause');
  await waitFor('state "paused"', async () => (await text(page, '#run-state')) === 'paused', 10_000);
  // The step under way when the pause arrived still completes and its metrics follow: wait
  // until the count has settled (unchanged for 1 s), then require it to stay put for 2 s.
  let previous = await stepOf(page);
  const { pausedStep } = await waitFor('the step count to settle after the pause', async () => {
    await page.waitForTimeout(1000);
    const now = await stepOf(page);
    const settled = now === previous;
    previous = now;
    return settled ? { pausedStep: now } : null;
  }, 10_000);
  await page.waitForTimeout(2000);
  const stillStep = await stepOf(page);
  if (stillStep !== pausedStep) fail(`the step count advanced while paused: ${pausedStep} → ${stillStep}`);
  if (!(await page.locator('#btn-resume').isEnabled()) || (await page.locator('#btn-pause').isEnabled()))
    fail('while paused, Resume should be enabled and Pause disabled');
  pass(`paused: step stays at ${pausedStep} for 2 s, Resume enabled`);

  // Full history after a reload: while paused nothing new arrives, so whatever the plots show
  // after the reload came from the server's histories (timeseries, analysis).
  currentStep = 'reloading while paused';
  const statsBefore = Number(await page.locator('#chart-stats').getAttribute('data-points'));
  if (!(statsBefore > 1)) fail(`the sub-filter stress plot has ${statsBefore} points before the reload`);
  await page.reload();
  await waitFor('the paused run selected again', async () => (await text(page, '#run-state')) === 'paused', 10_000);
  const statsAfter = await waitFor('the sub-filter stress history after the reload', async () => {
    const n = Number(await page.locator('#chart-stats').getAttribute('data-points'));
    return n >= statsBefore ? n : 0;
  }, 10_000);
  const energyAfter = Number(await page.locator('#chart-energy').getAttribute('data-points'));
  if (!(energyAfter >= pausedStep)) fail(`e_v has ${energyAfter} points after the reload, the run ${pausedStep} steps`);
  pass(`after a reload the plots have the whole history: ${statsAfter} analysis frames (${statsBefore} before), ${energyAfter} e_v samples`);

  // Resume: running again and the step count advances.
  currentStep = 'resuming';
  await page.click('#btn-resume');
  await waitFor('state "running" after resume', async () => (await text(page, '#run-state')) === 'running', 10_000);
  const resumedStep = await waitFor('the step count to advance after resume', async () => {
    const s = await stepOf(page);
    return s > pausedStep ? s : 0;
  }, 15_000);
  pass(`resumed: step ${pausedStep} → ${resumedStep}`);

  currentStep = 'stopping';
  await page.click('#btn-stop');
  await waitFor('state "stopped"', async () => (await text(page, '#run-state')) === 'stopped', 20_000);
  pass('stopped');

  // The end time and the viscosity are in the parameter form: a stopped (or finished) run can be
  // given a later end and another viscosity before it is resumed.
  currentStep = 'changing time.end and the viscosity of the stopped run';
  await page.fill('#p-end', String(2 * END_TIME));
  await page.fill('#p-eta', '0.02');
  await page.click('#param-apply');
  await waitFor('the change to be accepted', async () => /^Changed: /.test(await text(page, '#param-status')), 10_000);
  {
    const runs = await (await fetch(`${base}/api/runs`)).json();
    const mine = runs.find((r) => r.name === 'e2e-tgv2d');
    const scene = (await (await fetch(`${base}/api/runs/${mine.id}`)).json()).scene;
    if (scene?.time?.end !== 2 * END_TIME || scene?.fluid?.dynamic_viscosity !== 0.02)
      fail(`the run's scene did not take the form's values: time.end ${scene?.time?.end}, η ${scene?.fluid?.dynamic_viscosity}`);
  }
  pass('time.end and η changed from the parameter form');

  // Run comparison: a second, finished run ticked "compare" overlays its e_v(t), ε(t) and E(k) on
  // the selected run's plots, E(k) at the time of the compare slider, with a table of both runs;
  // unticked, the overlay goes. (Created now that the first run is stopped: the test server runs
  // one run at a time.)
  currentStep = 'comparing runs';
  const other = await fetch(`${base}/api/runs`, {
    method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ preset: 'tgv2d', name: 'e2e-compare', patch: {
      particles_per_side: 16, time: { end: 0.3 }, analysis: { every: 0.1, products: ['spectrum'] } } }),
  });
  if (other.status !== 201) fail(`creating the run to compare: HTTP ${other.status}`);
  const otherId = (await other.json()).id;
  await waitFor('the run to compare to finish', async () =>
    (await (await fetch(`${base}/api/runs/${otherId}`)).json()).state === 'finished', 60_000);
  const compareBox = page.locator(`#run-list li[data-id="${otherId}"] .compare input`);
  await waitFor('its compare box in the list', async () => (await compareBox.count()) === 1, 10_000);
  if (await page.locator('#compare-time').isVisible()) fail('the compare slider shows with nothing compared');
  await compareBox.check();
  const overlaid = await waitFor('the compared run on the e_v and ε plots', async () => {
    const points = await Promise.all(['#chart-energy', '#chart-dissipation'].map(
      async (sel) => Number(await page.locator(sel).getAttribute('data-compare-points'))));
    return points.every((n) => n > 0) ? points : null;
  }, 15_000);
  if ((await text(page, '#run-title')) !== 'e2e-tgv2d') fail('ticking compare changed the selected run');
  // E(k) at equal times: at the slider's right end (the selected run's latest spectrum, seconds
  // in) the compared run, finished at t = 0.3, has not got there and is not drawn ...
  const spectrumShown = () => page.locator('#chart-spectrum').evaluate((el) => ({ ...el.dataset }));
  const slider = page.locator('#compare-slider');
  await waitFor('the compare slider over the run\'s spectra at "latest", the compared run not reached', async () => {
    const shown = await spectrumShown();
    return (await page.locator('#compare-time').isVisible()) && (await slider.isEnabled()) &&
      shown.compareTimes === 'none' && /^latest/.test(await text(page, '#compare-label')) &&
      /not reached/.test(await text(page, '#cap-compare'));
  }, 10_000);
  // ... and at t = 0.1 s, moved there from the keyboard, both runs' spectra of that time are.
  await slider.focus();
  await slider.press('Home');
  await waitFor('the slider at t = 0.1 s', async () => {
    if (/^t = 0\.1 s$/.test(await text(page, '#compare-label'))) return true;
    await slider.press('ArrowRight');
    await page.waitForTimeout(300);  // the redraw that labels it
    return false;
  }, 10_000);
  const near01 = (v) => v !== '' && Math.abs(Number(v) - 0.1) < 1e-6;
  const atTime = await waitFor('both runs\' spectra of t = 0.1 s on the E(k) plot', async () => {
    const shown = await spectrumShown();
    return near01(shown.ownTime) && shown.compareTimes.split(',').every(near01) &&
      Number(shown.comparePoints) > 0 && Number(shown.points) > 0 ? shown : null;
  }, 10_000);
  // The table: one row per run, the selected one first, with its live-changed η; neither flow
  // has a reference run, and the table says so rather than showing a number.
  const tableRows = () => page.locator('#compare-table tbody tr').evaluateAll((trs) => trs.map((tr) => ({
    id: tr.dataset.id, name: tr.querySelector('th').textContent,
    ...Object.fromEntries([...tr.querySelectorAll('td')].map((td) =>
      [td.dataset.field, { text: td.textContent, value: td.dataset.value ?? null, title: td.title }])),
  })));
  const rows = await waitFor('the comparison table with both runs', async () => {
    const r = await tableRows();
    return r.length === 2 && r.every((row) => row.kernel.text !== '–') && r[0].eta.value === '0.02' ? r : null;
  }, 10_000);
  const kernelOf = async (id) => (await (await fetch(`${base}/api/runs/${id}`)).json()).scene.kernel.type;
  const runsNow = await (await fetch(`${base}/api/runs`)).json();
  const firstId = runsNow.find((r) => r.name === 'e2e-tgv2d').id;
  if (rows[0].id !== firstId || rows[1].id !== otherId || rows[0].n.text !== `${PARTICLES_PER_SIDE}²` ||
      rows[1].n.text !== '16²' || rows[0].kernel.text !== await kernelOf(firstId) ||
      rows[1].kernel.text !== await kernelOf(otherId) || rows[0].dk.value !== '7')
    fail(`the comparison table's rows: ${JSON.stringify(rows.map((r) => [r.id, r.n.text, r.kernel.text, r.dk.text]))}`);
  if (!rows.every((r) => r.misfit.text === '–' && /no reference run/.test(r.misfit.title)))
    fail(`the table gives errors without a reference: ${JSON.stringify(rows.map((r) => r.misfit))}`);
  if (screenshot) {
    const shot = screenshot.replace(/(\.png)?$/, '-compare.png');
    await page.locator('section:has(#plots-heading)').screenshot({ path: shot });
    log(`screenshot: ${shot}`);
  }
  await compareBox.uncheck();
  await waitFor('the overlay, the slider and the table gone', async () =>
    Number(await page.locator('#chart-energy').getAttribute('data-compare-points')) === 0 &&
    await page.locator('#compare-time').isHidden() && await page.locator('#compare-panel').isHidden(), 10_000);
  pass(`run comparison: e2e-compare overlaid (${overlaid.join(', ')} points on e_v, ε); E(k) at equal times ` +
    `(not reached at the latest, ${atTime.comparePoints} points at t = 0.1 s); a table of both runs ` +
    `(${rows.map((r) => `${r.name} ${r.n.text} ${r.kernel.text}`).join(', ')}); removed`);
  const otherRemoved = await fetch(`${base}/api/runs/${otherId}`, { method: 'DELETE' });
  if (otherRemoved.status !== 204 && otherRemoved.status !== 200) fail(`deleting the compared run: HTTP ${otherRemoved.status}`);

  // The resolved scales (SPEC §9) of a 3D Taylor-Green run at Re = 1600 against the reference run
  // shipped in data/reference/: the reference's E(k) dashed on the spectrum plot, E_res(t) beside
  // e_v(t) and the table of the shell ratios.
  currentStep = 'resolved scales';
  // D_K = 4 Δl: k_SPH = 2, where the reference holds the flow's energy, so that E_res has errors.
  const re1600Id = await selectFinishedTgv3d(base, 'e2e-re1600', 6.25e-4, { diameter_over_spacing: 4 });
  const resolved = await waitFor('the reference spectrum and the resolved-scales table', async () => {
    const refPoints = Number(await page.locator('#chart-spectrum').getAttribute('data-reference-points'));
    const shells = Number(await page.locator('#resolved-table').getAttribute('data-shells'));
    const energyPoints = Number(await page.locator('#chart-energy').getAttribute('data-resolved-points'));
    return refPoints > 0 && shells > 0 && energyPoints > 0 ? { refPoints, shells, energyPoints } : null;
  }, 20_000);
  const against = await text(page, '#cap-resolved');
  if (!against.includes('tgv3d_re1600')) fail(`the resolved scales name no Re = 1600 reference: "${against}"`);
  pass(`resolved scales of a Re = 1600 run ${against}: ${resolved.refPoints} reference E(k) points, ${resolved.shells} shell ratios, E_res(t) at ${resolved.energyPoints} times beside e_v`);
  // Compared with the stopped 2D run, the table gives this run's errors against its reference.
  const firstBox = page.locator(`#run-list li[data-id="${firstId}"] .compare input`);
  await firstBox.check();
  const errors = await waitFor('the Re = 1600 run\'s errors in the comparison table', async () => {
    const r = await tableRows();
    const fields = ['misfit', 'max_error', 'ratio'];
    return r.length === 2 && r[0].id === re1600Id && r[0].n.text === '16³' &&
      fields.every((f) => Number.isFinite(Number(r[0][f].value)) && r[0][f].value !== null) &&
      fields.every((f) => r[1][f].text === '–') ? fields.map((f) => `${f} ${r[0][f].text}`) : null;
  }, 10_000);
  await firstBox.uncheck();
  await waitFor('the comparison table gone', async () => page.locator('#compare-panel').isHidden(), 10_000);
  pass(`comparison table against the reference: ${errors.join(', ')}`);
  const re1600Removed = await fetch(`${base}/api/runs/${re1600Id}`, { method: 'DELETE' });
  if (re1600Removed.status !== 204 && re1600Removed.status !== 200) fail(`deleting the Re = 1600 run: HTTP ${re1600Removed.status}`);

  // A flow without a reference run (Re = 1000): the panel offers to compute one; its estimate,
  // then the job (16³ to t = 0.5, well under a second), then the resolved scales against it.
  currentStep = 'compute reference';
  const re1000Id = await selectFinishedTgv3d(base, 'e2e-re1000', 1e-3);
  await waitFor('the Compute reference form', async () => page.locator('#reference-form').isVisible(), 20_000);
  await page.locator('#reference-points').fill('16');
  await page.locator('#reference-estimate').click();
  const estimate = await waitFor('the reference\'s estimate', async () => {
    const t = await text(page, '#reference-status');
    return /fits\.$/.test(t) ? t : null;
  }, 10_000);
  await page.locator('#reference-compute').click();
  const computed = await waitFor('the resolved scales against the computed reference', async () => {
    const shells = Number(await page.locator('#resolved-table').getAttribute('data-shells'));
    const against = await text(page, '#cap-resolved');
    return shells > 0 && /e2e-re1000-n16/.test(against) ? against : null;
  }, 30_000);
  if (await page.locator('#reference-form').isVisible()) fail('the Compute reference form stays beside the resolved scales');
  pass(`reference computed from the dashboard (${estimate}); resolved scales ${computed}`);
  const re1000Removed = await fetch(`${base}/api/runs/${re1000Id}`, { method: 'DELETE' });
  if (re1000Removed.status !== 200) fail(`deleting the Re = 1000 run: HTTP ${re1000Removed.status}`);
  await page.locator('#run-list li button', { hasText: 'e2e-tgv2d' }).click();
  await waitFor('the first run selected again', async () => (await text(page, '#run-title')) === 'e2e-tgv2d', 10_000);

  // Downloads: the stopped run's files, its final checkpoint among them, as links that fetch the
  // files themselves.
  currentStep = 'files';
  const fileCount = await waitFor('the run\'s files listed', async () => {
    const n = Number(await page.locator('#run-files').getAttribute('data-count'));
    return (await page.locator('#run-files a[href$=".h5"]').count()) > 0 ? n : 0;
  }, 10_000);
  const seriesHref = await page.locator('#run-files a[href$="/timeseries.csv"]').getAttribute('href');
  const seriesText = await (await fetch(`${base}${seriesHref}`)).text();
  if (!seriesText.startsWith('t,step,')) fail(`the timeseries.csv link gives: ${seriesText.slice(0, 80)}`);
  const h5Href = await page.locator('#run-files a[href$=".h5"]').first().getAttribute('href');
  const h5 = new Uint8Array(await (await fetch(`${base}${h5Href}`)).arrayBuffer());
  if (h5.length < 8 || String.fromCharCode(...h5.slice(1, 4)) !== 'HDF') fail(`${h5Href} is not an HDF5 file`);
  pass(`files listed for download (${fileCount}): timeseries.csv and the checkpoint (${h5.length} B, HDF5 signature) fetched from their links`);
  // The whole run as one tar archive: every listed file is a member under RUN_ID/.
  const archiveHref = await page.locator('#run-archive a').getAttribute('href');
  const tar = new Uint8Array(await (await fetch(`${base}${archiveHref}`)).arrayBuffer());
  const tarText = (from, length) => String.fromCharCode(...tar.slice(from, from + length)).replace(/\0.*$/s, '');
  const members = [];
  for (let at = 0; at + 512 <= tar.length && tar[at] !== 0;) {
    const size = parseInt(tarText(at + 124, 12), 8);
    if (tarText(at + 257, 5) !== 'ustar' || !Number.isFinite(size)) fail(`${archiveHref}: no ustar header at byte ${at}`);
    if (tarText(at + 156, 1) === '0') members.push(tarText(at, 100));
    at += 512 + Math.ceil(size / 512) * 512;
  }
  const runId = archiveHref.split('/')[3];
  if (members.length !== fileCount || !members.every((m) => m.startsWith(`${runId}/`)) || !members.includes(`${runId}/timeseries.csv`))
    fail(`${archiveHref}: ${members.length} members (${members.slice(0, 5).join(', ')}…) for ${fileCount} listed files`);
  pass(`the whole run downloads as one tar archive (${tar.length} B, ${members.length} members under ${runId}/)`);

  // Movie: the saved ω² frames as a WebM video that the browser itself decodes.
  currentStep = 'making a movie';
  await page.click('#btn-movie');
  const movie = await waitFor('the movie to load in the page', async () => page.evaluate(() => {
    const v = document.getElementById('movie');
    return !v.hidden && v.readyState >= 1 && v.duration > 0 && v.videoWidth > 0
      ? { frames: Number(v.dataset.frames), duration: v.duration, width: v.videoWidth, height: v.videoHeight }
      : null;
  }), 20_000);
  if (!(movie.frames >= 2) || Math.abs(movie.duration - movie.frames / 10) > 0.2)
    fail(`the movie's duration ${movie.duration} s does not match ${movie.frames} frames at 10 frames/s`);
  pass(`the Movie button makes a video Chromium plays: ${movie.frames} frames, ${movie.width}×${movie.height} px, ${movie.duration.toFixed(1)} s`);

  // Delete: after the confirmation the run leaves the list and the server.
  currentStep = 'deleting';
  const runs = await (await fetch(`${base}/api/runs`)).json();
  const created = runs.find((r) => r.name === 'e2e-tgv2d');
  if (!created) fail('the created run is not in GET /api/runs');
  const detail = await (await fetch(`${base}/api/runs/${created.id}`)).json();
  const scheme = detail.scene?.scheme ?? {};
  if (scheme.type !== 'transport_velocity' || scheme.ale_correction !== 'full')
    fail(`the run's scheme is not the form's choice: ${JSON.stringify(scheme)}`);
  if (detail.scene?.kernel?.diameter_over_spacing !== 7)
    fail(`the run's D_K/Δl is not the form's 7: ${detail.scene?.kernel?.diameter_over_spacing}`);
  if (!(await page.locator('#create-eta').count())) fail('the form offers no viscosity η');
  pass('scheme, ALE correction and D_K/Δl chosen in the form are the run\'s; η is offered');
  const products = detail.scene?.analysis?.products ?? [];
  if (!products.includes('particles') || !products.includes('spectrum'))
    fail(`the run's analysis products are not the form's choice: ${JSON.stringify(products)}`);
  const snapshotFiles = await waitFor('a particle snapshot in the run\'s files', async () => {
    const files = await (await fetch(`${base}/api/runs/${created.id}/files`)).json();
    const list = (files.files ?? files).filter((f) => /^snapshots\/particles_.*\.h5$/.test(f.path ?? f.name ?? ''));
    return list.length ? list : null;
  }, 20_000);
  pass(`the particle snapshot product chosen in the form is written (${snapshotFiles.length} snapshot files)`);
  if (detail.ranks !== 2) fail(`the run's rank count is not the form's 2: ${detail.ranks}`);
  if (!(await text(page, '#run-case')).includes('2 MPI ranks')) fail('the run detail does not show its 2 MPI ranks');
  pass('the run was created with the form\'s 2 MPI ranks and shows them');

  // Clone with edits: the form takes the run's whole scene; an edited end time goes as a patch
  // over it, and everything else (scheme, the live-changed η, ranks) is the run's.
  currentStep = 'cloning';
  await page.click('#btn-clone');
  await waitFor('the form to take the run\'s scene', async () =>
    /clone of/.test(await page.locator('#create-preset option:checked').textContent()), 5_000);
  if ((await page.inputValue('#create-particles')) !== String(PARTICLES_PER_SIDE) ||
      (await page.inputValue('#create-scheme')) !== 'transport_velocity')
    fail('the form does not show the cloned run\'s particles and scheme');
  await page.fill('#create-end', '7');
  await page.uncheck('#create-start');
  await page.click('#create-submit');
  await waitFor('the clone selected', async () => (await text(page, '#run-title')) === 'e2e-tgv2d-clone', 10_000);
  const clone = (await (await fetch(`${base}/api/runs`)).json()).find((r) => r.name === 'e2e-tgv2d-clone');
  const cloneDetail = await (await fetch(`${base}/api/runs/${clone.id}`)).json();
  const cs = cloneDetail.scene;
  if (cs.time?.end !== 7 || cs.scheme?.type !== 'transport_velocity' || cs.scheme?.ale_correction !== 'full' ||
      cs.fluid?.dynamic_viscosity !== 0.02 || cs.particles_per_side !== PARTICLES_PER_SIDE || cloneDetail.ranks !== 2)
    fail(`the clone's scene is not the run's with the edit: ${JSON.stringify({ end: cs.time?.end, scheme: cs.scheme, eta: cs.fluid?.dynamic_viscosity, n: cs.particles_per_side, ranks: cloneDetail.ranks })}`);
  pass(`cloned with an edited end time: ${clone.id} has the run's scheme, η, particles and ranks, and time.end = 7`);
  page.once('dialog', (d) => d.accept());
  await page.click('#btn-delete');
  await waitFor('the clone deleted', async () => page.locator('#run-detail').isHidden(), 10_000);
  // ... and stays closed: no run list asked for before the delete re-selects the deleted run,
  // and the page picks no other run for the user (one poll period and more).
  await page.waitForTimeout(2_500);
  if (await page.locator('#run-detail').isVisible())
    fail(`after the delete the page selected run "${await text(page, '#run-title')}"`);
  // The run's reference requests are held until after its delete: the page must cancel what it
  // still has under way for the run, so that nothing of it reaches the server once it is gone
  // (a held GET let through after the DELETE answers 404, which fails the page-error check).
  const heldReference = [];
  const referencePattern = `**/api/runs/${created.id}/reference*`;
  await page.route(referencePattern, (route) => { heldReference.push(route); });
  await page.locator(`#run-list li[data-id="${created.id}"] button`).click();
  await waitFor('the original run selected again', async () => (await text(page, '#run-title')) === 'e2e-tgv2d', 10_000);
  await waitFor('the run\'s reference request under way', async () => heldReference.length > 0, 10_000);
  page.once('dialog', (d) => d.accept());
  await page.click('#btn-delete');
  await waitFor('the run detail to close after delete', async () => page.locator('#run-detail').isHidden(), 10_000);
  await page.unroute(referencePattern);
  for (const route of heldReference) await route.continue().catch(() => {});
  await page.waitForTimeout(300);
  const after = await (await fetch(`${base}/api/runs`)).json();
  if (after.some((r) => r.id === created.id)) fail(`run ${created.id} is still listed after delete`);
  pass(`deleted run ${created.id}: gone from the dashboard and GET /api/runs`);

  // A forced flow shows its energy budget and u_rms in place of −deᵥ/dt (SPEC §6.3): the
  // injection, the film's friction, ν⟨ω²⟩ at the analysis times and the rest the scheme takes.
  currentStep = 'a forced flow';
  const forced = await fetch(`${base}/api/runs`, {
    method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ preset: 'kolmogorov2d', name: 'e2e-kolmogorov',
      patch: { particles_per_side: 24, box_length: 0.012, forcing: { periods: 2 },
        packing: { enabled: false }, time: { end: 0.2 },
        analysis: { every: 0.02, products: ['energy', 'vorticity'] }, render: { fields: [] } } }),
  });
  if (forced.status !== 201) fail(`creating the forced run: HTTP ${forced.status} ${await forced.text()}`);
  const forcedId = (await forced.json()).id;
  const forcedItem = page.locator(`#run-list li[data-id="${forcedId}"] button`);
  await waitFor('the forced run in the list', async () => (await forcedItem.count()) === 1, 10_000);
  await forcedItem.click();
  await waitFor('state "finished"', async () => (await text(page, '#run-state')) === 'finished', 30_000);
  const budgetPoints = await waitFor('ν⟨ω²⟩ at ten analysis times in the budget', async () => {
    const n = Number(await page.locator('#chart-budget').getAttribute('data-viscous-points'));
    return n >= 10 ? n : null;
  }, 15_000);
  if (!(await page.locator('#fig-dissipation').isHidden())) fail('the forced flow still shows −deᵥ/dt as its dissipation');
  if (!(await page.locator('#fig-urms').isVisible())) fail('the forced flow shows no u_rms');
  const rest = Number(await page.locator('#chart-budget').getAttribute('data-rest-mean'));
  const budgetCaption = await text(page, '#cap-budget');
  if (!Number.isFinite(rest) || !/injection .* film .* viscous .* rest .*u_rms/.test(budgetCaption))
    fail(`the budget's caption has no averages: "${budgetCaption}" (rest ${rest})`);
  if (Number(await page.locator('#chart-urms').getAttribute('data-points')) < 10) fail('the u_rms plot has no points');
  pass(`a forced flow shows its budget (${budgetPoints} analysis times; ${budgetCaption.slice(0, 90)}…) and u_rms`);

  // A 3D run with an iso-surface view: its panel appears with the rendered picture.
  currentStep = 'an iso-surface view';
  const iso = await fetch(`${base}/api/runs`, {
    method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ preset: 'tgv3d', name: 'e2e-isosurface',
      patch: { particles_per_side: 12, kernel: { diameter_over_spacing: 4 }, packing: { enabled: false },
        time: { end: 0.2 },
        analysis: { every: 0.1, products: ['slices', 'fields'], grid_fields: ['omega2'],
          slice: { axis: 'x', position: Math.PI, fields: ['omega2'] } },
        render: { fields: ['omega2'], combined: false,
          view3d: { enabled: true, kind: 'isosurface', field: 'omega2', width: 320, height: 320 } } } }),
  });
  if (iso.status !== 201) fail(`creating the iso-surface run: HTTP ${iso.status} ${await iso.text()}`);
  const isoId = (await iso.json()).id;
  const isoItem = page.locator(`#run-list li[data-id="${isoId}"] button`);
  await waitFor('the iso-surface run in the list', async () => (await isoItem.count()) === 1, 10_000);
  await isoItem.click();
  const isoStep = await waitFor('the 3D view panel with its picture', async () => {
    if (await page.locator('#fig-view3d').isHidden()) return null;
    const loaded = await page.evaluate(() => {
      const img = document.getElementById('img-view3d');
      return img.complete && img.naturalWidth === 320 ? img.dataset.step : null;
    });
    return loaded || null;
  }, 30_000);
  pass(`an iso-surface run shows its 3D view (320×320 px, step ${isoStep})`);

  // A failed run shows its diagnosis as an error: 3 MPI ranks cannot split a 12² box with a halo
  // as wide as the kernel's list radius, which the job refuses, naming why.
  currentStep = 'a failing run';
  const failing = await fetch(`${base}/api/runs`, {
    method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ preset: 'tgv3d', name: 'e2e-fails', ranks: 3,
      patch: { case: 'tgv2d', particles_per_side: 12, packing: { enabled: false } } }),
  });
  if (failing.status !== 201) fail(`creating the failing run: HTTP ${failing.status} ${await failing.text()}`);
  const failingId = (await failing.json()).id;
  const failingItem = page.locator(`#run-list li[data-id="${failingId}"] button`);
  await waitFor('the failing run in the list', async () => (await failingItem.count()) === 1, 10_000);
  await failingItem.click();
  await waitFor('state "failed"', async () => (await text(page, '#run-state')) === 'failed', 60_000);
  await waitFor('the failure shown', async () => page.locator('#run-failure').isVisible(), 5_000);
  const diagnosis = await text(page, '#run-failure');
  if (!/narrower than the halo width/.test(diagnosis) || !/3 MPI ranks/.test(diagnosis))
    fail(`the failure does not show the diagnosis: ${diagnosis}`);
  pass(`a failed run shows its diagnosis as an error: "${diagnosis.slice(0, 80)}…"`);
  await waitFor('the failure in the run log', async () =>
    / error state: \w+ -> failed: .*narrower than the halo width/.test(await text(page, '#run-log')), 10_000);
  pass('the run log has the failure at error level');

  if (consoleErrors.length) fail(`the page logged errors:\n  ${consoleErrors.join('\n  ')}`);
  pass('no console errors or uncaught exceptions');
}

const watchdog = setTimeout(() => {
  console.error(`web_e2e: FAILED: over the ${DEADLINE_MS / 1000} s limit while ${currentStep}`);
  if (server && server.exitCode === null) server.kill('SIGKILL');
  process.exit(1);
}, DEADLINE_MS);

let exitCode = 0;
try {
  await run();
  console.log(`web_e2e: ${checks.length} checks passed in ${elapsed()}`);
} catch (e) {
  exitCode = 1;
  console.error(`web_e2e: FAILED while ${currentStep}: ${e instanceof CheckFailed ? e.message : e.stack}`);
  if (consoleErrors.length) console.error(`page errors:\n  ${consoleErrors.join('\n  ')}`);
  if (page) {
    const shown = await page.evaluate(() => ['run-state', 'run-step', 'control-status', 'ws-state',
      'api-state', 'create-status', 'param-status'].map((id) => {
      const el = document.getElementById(id);
      return `${id}: ${el ? el.textContent.trim() : '(missing)'}`;
    })).catch(() => []);
    if (shown.length) console.error(`page shows:\n  ${shown.join('\n  ')}`);
  }
  if (serverOutput) console.error(`--- server output (last 4000 characters) ---\n${serverOutput.slice(-4000)}`);
} finally {
  try {
    if (browser) await browser.close();
  } catch {
    // the browser may already be gone
  }
  await stopServer();
  if (dataDir) rmSync(dataDir, { recursive: true, force: true });
  clearTimeout(watchdog);
}
process.exit(exitCode);
