// End-to-end test of the dashboard in a real browser (Debian's chromium, driven by playwright-core):
// submit the "Quick check" preset on /, follow the job to `succeeded` on its page, check that the
// wear-curve and histogram plots are there, and save screenshots: the jobs page, a job's page, a
// schedule's trend over a few runs, a job's Weibull plot, two designs compared (through the job
// page's form: both overlaid plots and the tables) and a job's sensitivity analysis (its
// section shown, its Sobol' plot and table, hidden on a job without one); a job submitted through
// the API joins the open list, a refused job names each field once, and a job deleted while its
// page is open says so. Then under load: with 20 active
// jobs and a schedule, every plot of both pages loads within 5 s and a submit through the form is
// accepted while they run (Chromium opens at most 6 connections per host: the page must not hold
// one stream per job).
//
//   node tests/browser/dashboard.mjs BASE_URL OUT_DIR
//
// BOUNCEWEAR_API_KEY, when set, is stored as the dashboard's key before the pages load.
// Exits 0 on success; on any failure prints one line starting "dashboard test FAILED:", saves
// OUT_DIR/dashboard-failure.png when it can, and exits 1.

import { chromium } from "playwright-core";
import { mkdirSync } from "node:fs";
import { join } from "node:path";

const [baseArg, outDir] = process.argv.slice(2);
if (!baseArg || !outDir) {
  console.error("usage: node dashboard.mjs BASE_URL OUT_DIR");
  process.exit(2);
}
const base = baseArg.replace(/\/+$/, "");
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";
const JOB_TIMEOUT_MS = 120_000;
const STEP_TIMEOUT_MS = 30_000;
const OVERALL_TIMEOUT_MS = 300_000;
const ACTIVE_JOBS = 20;
const PLOT_TIMEOUT_MS = 5_000;
// Runs of the schedule before the trend is photographed: enough for a line with drift flags.
const TREND_RUNS = 4;

mkdirSync(outDir, { recursive: true });

let browser;
let page;
const pageErrors = [];
const consoleErrors = [];

function log(message) {
  console.log(`dashboard test: ${message}`);
}

async function fail(message) {
  console.error(`dashboard test FAILED: ${message}`);
  if (pageErrors.length) console.error(`  page errors: ${pageErrors.join(" | ")}`);
  if (consoleErrors.length) console.error(`  console errors: ${consoleErrors.slice(0, 10).join(" | ")}`);
  if (page) {
    await page
      .screenshot({ path: join(outDir, "dashboard-failure.png"), fullPage: true, timeout: 10_000 })
      .then(() => console.error(`  screenshot: ${join(outDir, "dashboard-failure.png")}`))
      .catch(() => {});
  }
  if (browser) await browser.close().catch(() => {});
  console.error("browser: 0 passed, 1 failed");
  process.exit(1);
}

/** Runs `action`; a rejection fails the test with `what` and the reason. */
async function step(what, action) {
  try {
    return await action();
  } catch (error) {
    await fail(`${what}: ${String((error && error.message) || error).split("\n")[0]}`);
  }
}

const watchdog = setTimeout(() => {
  fail(`the whole test took longer than ${OVERALL_TIMEOUT_MS / 1000} s`);
}, OVERALL_TIMEOUT_MS);

browser = await step(`launch ${CHROMIUM}`, () =>
  chromium.launch({
    executablePath: CHROMIUM,
    args: [
      "--headless",
      "--no-sandbox",
      "--disable-gpu",
      "--disable-quic",
      "--no-first-run",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
    ],
  }),
);
const context = await step("open a browser context", () =>
  browser.newContext({ viewport: { width: 1280, height: 900 } }),
);
const apiKey = process.env.BOUNCEWEAR_API_KEY || "";
if (apiKey) {
  await context.addInitScript((key) => localStorage.setItem("bouncewear.apiKey", key), apiKey);
}
page = await step("open a page", () => context.newPage());
page.setDefaultTimeout(STEP_TIMEOUT_MS);
page.on("pageerror", (error) => pageErrors.push(String(error.message || error)));
page.on("console", (message) => {
  if (message.type() === "error") consoleErrors.push(message.text());
});

// 1. The jobs page: pick the Quick check preset and submit it.
log(`opening ${base}/`);
const home = await step(`open ${base}/`, () => page.goto(`${base}/`, { waitUntil: "load" }));
if (!home || !home.ok()) await fail(`GET ${base}/ answered ${home ? home.status() : "nothing"}`);
await step("the preset selector has options", () => page.waitForSelector("#preset option", { state: "attached" }));
const quick = await page.$$eval("#preset option", (options) => {
  const option = options.find((o) => o.textContent.trim().startsWith("Quick check"));
  return option ? option.value : null;
});
if (!quick) await fail('no "Quick check" preset in #preset');
await step("select the Quick check preset", () => page.selectOption("#preset", quick));
const jobText = await page.inputValue("#job-json");
let jobJson;
try {
  jobJson = JSON.parse(jobText);
} catch (error) {
  await fail(`the preset's JSON does not parse: ${error.message}`);
}
if (jobJson.devices !== 100 || jobJson.operations !== 100) {
  await fail(`the Quick check preset is not 100 x 100: ${jobText.slice(0, 200)}`);
}

log("submitting the Quick check job");
const [response] = await step("submit the job", () =>
  Promise.all([
    page.waitForResponse((r) => new URL(r.url()).pathname === "/v1/jobs" && r.request().method() === "POST"),
    page.click("#submit-button"),
  ]),
);
if (response.status() !== 202) {
  const shown = await page.textContent("#submit-errors").catch(() => "");
  await fail(`POST /v1/jobs answered ${response.status()}: ${shown || (await response.text())}`);
}
const job = await response.json();
if (!job || typeof job.id !== "string") await fail(`POST /v1/jobs gave no job id: ${JSON.stringify(job)}`);
log(`job ${job.id} submitted`);
const rowSelector = `#jobs-body tr[data-job-id="${job.id}"]`;
await step("the new job's row appears in the jobs table", () => page.waitForSelector(rowSelector));
const link = await page.getAttribute(`${rowSelector} a`, "href");
if (link !== `/jobs/${encodeURIComponent(job.id)}`) await fail(`the row links to ${link}, not /jobs/${job.id}`);

// 2. The job page: follow it to the end, then the plots.
log(`opening ${base}${link}`);
await step(`open ${base}${link}`, () => page.goto(`${base}${link}`, { waitUntil: "load" }));
const finalStatus = await step(`the job ends within ${JOB_TIMEOUT_MS / 1000} s`, async () => {
  await page.waitForFunction(
    () => ["succeeded", "failed", "cancelled", "not found", "unavailable"].includes(
      (document.querySelector("#job-status") || {}).textContent,
    ),
    null,
    { timeout: JOB_TIMEOUT_MS, polling: 250 },
  );
  return (await page.textContent("#job-status")).trim();
});
if (finalStatus !== "succeeded") {
  const shown = await page.textContent("#job-error").catch(() => "");
  await fail(`#job-status is "${finalStatus}", not "succeeded" (${shown.trim()})`);
}
log("job succeeded");
for (const id of ["#plot-bands", "#plot-histograms"]) {
  await step(`${id} shows an SVG`, () => page.waitForSelector(`${id} svg`));
  const count = await page.locator(`${id} svg`).count();
  if (count !== 1) await fail(`${id} holds ${count} SVG elements, expected 1`);
}
const bandsTitle = await page.textContent("#plot-bands svg title");
if (!bandsTitle || !bandsTitle.includes("total_bounce_s")) {
  await fail(`the wear curve is not of total_bounce_s: "${bandsTitle}"`);
}
await step("the device metrics table is filled", () => page.waitForSelector("#devices-table tbody tr"));
if (!(await page.locator("#sensitivity-section").isHidden())) {
  await fail("#sensitivity-section is shown for a job without a sensitivity analysis");
}
await page.waitForTimeout(300);
await step("save dashboard-job.png", () =>
  page.screenshot({ path: join(outDir, "dashboard-job.png"), fullPage: true }),
);
log(`saved ${join(outDir, "dashboard-job.png")}`);

// 3. Back on the jobs page: the job is listed as succeeded.
await step(`open ${base}/ again`, () => page.goto(`${base}/`, { waitUntil: "load" }));
await step("the job's row says succeeded", () => page.waitForSelector(`${rowSelector}[data-status="succeeded"]`));
await page.waitForLoadState("networkidle", { timeout: 10_000 }).catch(() => {});
await step("save dashboard.png", () => page.screenshot({ path: join(outDir, "dashboard.png"), fullPage: true }));
log(`saved ${join(outDir, "dashboard.png")}`);

// 4. Under load. The jobs and the schedule are made through the API, outside the browser.
const apiKeyHeader = apiKey ? { authorization: `Bearer ${apiKey}` } : {};
async function call(method, path, body) {
  const headers = { ...apiKeyHeader, accept: "application/json" };
  if (body !== undefined) headers["content-type"] = "application/json";
  const response = await fetch(`${base}${path}`, {
    method,
    headers,
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await response.text();
  if (!response.ok) throw new Error(`${method} ${path} answered ${response.status}: ${text.slice(0, 300)}`);
  return text ? JSON.parse(text) : null;
}

log("creating a schedule and running it once, so that its trend has a point");
const schedule = await step("create a schedule", () =>
  call("POST", "/v1/schedules", {
    name: "Nightly quick check",
    cron: "0 1 * * *",
    time_zone: "Europe/Berlin",
    // No seed: each run draws its own, and the scattered impact velocity moves the trend.
    template: {
      devices: 100,
      operations: 100,
      scenario: { circuit: { supply_voltage_v: 48, current_a: 15 } },
      scatter: [
        { parameter: "impact_velocity_m_s", per: "operation", distribution: { kind: "uniform", min: 0.2, max: 0.6 } },
      ],
    },
    statistics: ["operations.total_bounce_s.mean", "operations.bounce_count.p50"],
  }),
);
async function succeeds(id) {
  for (const started = Date.now(); Date.now() - started < JOB_TIMEOUT_MS; ) {
    const job = await call("GET", `/v1/jobs/${id}`);
    if (job.status === "succeeded") return;
    if (!["queued", "running"].includes(job.status)) throw new Error(`it ended ${job.status}`);
    await new Promise((resolve) => setTimeout(resolve, 250));
  }
  throw new Error("it did not end in time");
}
for (let k = 1; k <= TREND_RUNS; k++) {
  const run = await step(`run the schedule now (${k} of ${TREND_RUNS})`, () =>
    call("POST", `/v1/schedules/${schedule.id}/run`),
  );
  await step(`the schedule's run ${run.id} succeeds`, () => succeeds(run.id));
}

// A schedule's trend and a job's Weibull plot, for the README: the plot kinds the jobs above lack.
await step(`open ${base}/ for the trend`, () => page.goto(`${base}/`, { waitUntil: "load" }));
await step("the trend plot shows an SVG", () => page.waitForSelector("#schedules .plot svg"));
await step("save dashboard-trend.png", () =>
  page.locator("#schedules-section").screenshot({ path: join(outDir, "dashboard-trend.png") }),
);
log(`saved ${join(outDir, "dashboard-trend.png")}`);

// The list follows jobs made elsewhere (the API, another tab, a schedule) through its one stream.
const outsideJob = await step("submit a job through the API while the jobs page is open", () =>
  call("POST", "/v1/jobs", { name: "Submitted outside the page", devices: 10, operations: 10, seed: 7 }),
);
await step("the job submitted outside the page joins the list and ends there", () =>
  page.waitForSelector(`#jobs-body tr[data-job-id="${outsideJob.id}"][data-status="succeeded"]`, {
    timeout: JOB_TIMEOUT_MS,
  }),
);
// A burst from elsewhere (schedules firing together, a script): every job joins the list, each
// in its place by creation, whatever order their fetches answer in (5-7 of 20 were lost).
const burst = await step("submit 12 jobs at once through the API", () =>
  Promise.all(Array.from({ length: 12 }, (_, k) =>
    call("POST", "/v1/jobs", { name: `Burst ${k}`, devices: 4, operations: 4, seed: 100 + k }))),
);
await step("every job of the burst joins the list", () =>
  page.waitForFunction(
    (ids) => ids.every((id) => document.querySelector(`#jobs-body tr[data-job-id="${id}"]`)),
    burst.map((job) => job.id),
    { timeout: JOB_TIMEOUT_MS },
  ),
);
// A refused job: each field named once, the whole document as "(document)".
for (const [text, wanted] of [
  ['{"devices": -1, "operations": 0}', ["/devices", "/operations"]],
  ["[1]", ["(document)"]],
]) {
  await step(`submit ${text} through the form`, async () => {
    await page.fill("#job-json", text);
    await page.click("#submit-button");
    await page.waitForSelector("#submit-errors:not([hidden]) li");
  });
  const shown = await page.textContent("#submit-errors");
  for (const field of wanted) {
    const times = shown.split(field).length - 1;
    if (times !== 1) await fail(`the refusal of ${text} names ${field} ${times} times: "${shown}"`);
  }
}
const lifeJob = await step("submit a job with a failure criterion", () =>
  call("POST", "/v1/jobs", {
    name: "Life to 330 J of arc energy",
    scenario: { circuit: { supply_voltage_v: 48, current_a: 15 } },
    devices: 100,
    operations: 200,
    seed: 5,
    scatter: [
      { parameter: "contact_radius_m", per: "device", distribution: { kind: "uniform", min: 0.004, max: 0.0085 } },
      { parameter: "impact_velocity_m_s", per: "operation", distribution: { kind: "uniform", min: 0.1, max: 0.6 } },
    ],
    failure: { cumulative_arc_energy_j: { above: 330 } },
  }),
);
await step(`the life job ${lifeJob.id} succeeds`, () => succeeds(lifeJob.id));
await step(`open ${base}/jobs/${lifeJob.id}`, () => page.goto(`${base}/jobs/${lifeJob.id}`, { waitUntil: "load" }));
await step("#plot-weibull shows an SVG", () => page.waitForSelector("#plot-weibull svg"));
await step("the candidate fits are listed with Anderson-Darling", () =>
  // Four candidates, and the three-parameter Weibull where its likelihood has a maximum inside.
  page.waitForFunction(() => [4, 5].includes(document.querySelectorAll("#fits-table tbody tr").length)
    && document.querySelector("#fits-table thead").textContent.includes("Anderson-Darling")),
);
await step("B1 and B10 read off the Kaplan-Meier curve are listed", () =>
  page.waitForFunction(() => [...document.querySelectorAll("#life-table tbody tr")]
    .filter((row) => row.textContent.includes("Kaplan-Meier, no model")).length === 2),
);
await page.waitForTimeout(300);
await step("save dashboard-life.png", () =>
  page.locator("#life-section").screenshot({ path: join(outDir, "dashboard-life.png") }),
);
log(`saved ${join(outDir, "dashboard-life.png")}`);
// Another design to compare the life job with: smaller contacts, the same criterion.
const otherDesign = await step("submit a second design", () =>
  call("POST", "/v1/jobs", {
    name: "Smaller contacts",
    scenario: { circuit: { supply_voltage_v: 48, current_a: 15 } },
    devices: 100,
    operations: 200,
    seed: 6,
    scatter: [
      { parameter: "contact_radius_m", per: "device", distribution: { kind: "uniform", min: 0.003, max: 0.006 } },
      { parameter: "impact_velocity_m_s", per: "operation", distribution: { kind: "uniform", min: 0.1, max: 0.6 } },
    ],
    failure: { cumulative_arc_energy_j: { above: 330 } },
  }),
);
await step(`the second design ${otherDesign.id} succeeds`, () => succeeds(otherDesign.id));
await step(`reload ${base}/jobs/${lifeJob.id}`, () => page.goto(`${base}/jobs/${lifeJob.id}`, { waitUntil: "load" }));
await step("compare with the second design through the form", async () => {
  await page.waitForSelector("#compare-section");
  await page.fill("#compare-with", otherDesign.id);
  await page.click("#compare-form button[type=submit]");
});
await step("both compared plots show an SVG", async () => {
  // Or the page says why not: a comparison that failed shows its error and never its plots.
  const plots = Promise.all([
    page.waitForSelector("#plot-compare-bands svg"),
    page.waitForSelector("#plot-compare-weibull svg"),
  ]).then(() => null);
  const said = page.waitForSelector("#compare-error:not([hidden])")
    .then((alert) => alert.textContent(), () => null)
    .then((text) => text || new Promise(() => {}));
  const error = await Promise.race([plots, said]);
  if (error) throw new Error(`the page says: ${error}`);
});
const compareRows = await step("the comparison tables are filled", async () => {
  await page.waitForFunction(() => document.querySelectorAll("#compare-life-table tbody tr").length >= 3);
  return page.$$eval("#compare-table tbody tr, #compare-life-table tbody tr", (rows) => rows.map((r) => r.textContent));
});
if (!compareRows.some((r) => r.includes("outlasts")) || !compareRows.some((r) => r.startsWith("B10"))
  || !compareRows.some((r) => r.startsWith("B10, operations (Kaplan-Meier)"))) {
  await fail(`the comparison lists ${compareRows.join(" | ")}`);
}
if (!page.url().includes(`#`) || !page.url().includes(`compare=${otherDesign.id}`)) {
  await fail(`the page's address ${page.url()} does not link the comparison`);
}
// The address links the comparison: opened anew, the page compares at once and keeps the link
// (the metric written into the address used to drop it before the comparison read it).
const linked = page.url();
await step(`open the linked comparison ${linked}`, async () => {
  await page.goto("about:blank");
  await page.goto(linked, { waitUntil: "load" });
});
await step("the linked comparison opens with its plots and tables", async () => {
  await page.waitForSelector("#plot-compare-bands svg");
  await page.waitForFunction(() => document.querySelectorAll("#compare-life-table tbody tr").length >= 3);
});
if (!page.url().includes(`compare=${otherDesign.id}`) || !page.url().includes("metric=")) {
  await fail(`the reopened page's address ${page.url()} lost the comparison or the metric`);
}
// An address changed in place shows what it names (the page read it only when it loaded).
const linkedHash = new URL(linked).hash.slice(1);
await step("a metric changed in the address shows it and compares for it", async () => {
  const hash = new URLSearchParams(linkedHash);
  hash.set("metric", "e1");
  await page.evaluate((h) => { location.hash = h; }, hash.toString());
  await page.waitForFunction(() => document.querySelector("#metric").value === "e1"
    && document.querySelector("#compare-table thead th")?.textContent === "e1");
});
await step("the comparison taken out of the address is hidden", async () => {
  await page.evaluate(() => { location.hash = "metric=e1"; });
  await page.waitForFunction(() => document.querySelector("#compare-result").hidden
    && document.querySelector("#compare-with").value === "");
});
await step("the linked address again shows its comparison", async () => {
  await page.evaluate((h) => { location.hash = h; }, linkedHash);
  await page.waitForFunction((other) => !document.querySelector("#compare-result").hidden
    && document.querySelector("#compare-with").value === other
    && document.querySelector("#compare-table thead th")?.textContent === "total_bounce_s",
    otherDesign.id);
});
await step("a comparison left before its answer came stays away", async () => {
  // Its answer held back a second: the address moves on before it comes (it showed, late).
  await page.route("**/compare/**", async (route) => {
    await new Promise((done) => setTimeout(done, 1000));
    await route.continue();
  });
  await page.evaluate(() => { location.hash = "metric=total_bounce_s"; });
  await page.evaluate((h) => { location.hash = h; }, linkedHash);
  await page.evaluate(() => { location.hash = "metric=total_bounce_s"; });
  await page.waitForTimeout(1800);
  await page.unroute("**/compare/**");
  const [hidden, address] = await page.evaluate(() =>
    [document.querySelector("#compare-result").hidden, location.hash]);
  if (!hidden || address.includes("compare=")) {
    throw new Error(`the comparison came back: hidden ${hidden}, address ${address}`);
  }
});
await step("a failed comparison's error goes with it from the address", async () => {
  await page.evaluate(() => { location.hash = "metric=total_bounce_s&compare=no-such-job"; });
  await page.waitForSelector("#compare-error:not([hidden])");
  await page.evaluate(() => { location.hash = "metric=total_bounce_s"; });
  await page.waitForSelector("#compare-error", { state: "hidden" });
});
await step("a metric the job lacks in the address is written as the one shown", async () => {
  await page.evaluate(() => { location.hash = "metric=no_such_metric"; });
  await page.waitForFunction(() => location.hash === "#metric=" + document.querySelector("#metric").value);
});
await step("the linked comparison once more, for its screenshot", async () => {
  await page.evaluate((h) => { location.hash = h; }, linkedHash);
  await page.waitForFunction(() => !document.querySelector("#compare-result").hidden
    && document.querySelectorAll("#compare-life-table tbody tr").length >= 3);
});
await page.waitForTimeout(300);
await step("save dashboard-compare.png", () =>
  page.locator("#compare-section").screenshot({ path: join(outDir, "dashboard-compare.png") }),
);
log(`saved ${join(outDir, "dashboard-compare.png")}`);
const sensitivityJob = await step("submit a job with a sensitivity analysis", () =>
  call("POST", "/v1/jobs", {
    name: "Sobol' indices at 48 V",
    scenario: { circuit: { supply_voltage_v: 48, current_a: 15 } },
    devices: 100,
    operations: 100,
    bin_operations: 50,
    seed: 7,
    scatter: [
      { parameter: "impact_velocity_m_s", per: "operation", distribution: { kind: "normal", mean: 0.3, sd: 0.03, min: 0 } },
      { parameter: "dynamic_yield_pressure_pa", per: "device", distribution: { kind: "normal", mean: 1.0e9, sd: 1.0e8, min: 1e8 } },
      { parameter: "contact_radius_m", per: "device", distribution: { kind: "normal", mean: 3e-3, sd: 1e-4, min: 2e-3 } },
    ],
    sensitivity: { method: "sobol" },
  }),
);
await step(`the sensitivity job ${sensitivityJob.id} succeeds`, () => succeeds(sensitivityJob.id));
await step(`open ${base}/jobs/${sensitivityJob.id}`, () =>
  page.goto(`${base}/jobs/${sensitivityJob.id}`, { waitUntil: "load" }),
);
await step("#sensitivity-section is shown", () => page.waitForSelector("#sensitivity-section:not([hidden])"));
await step("#plot-sensitivity shows an SVG", () => page.waitForSelector("#sensitivity-section #plot-sensitivity svg"));
const sensitivityTitle = await page.textContent("#plot-sensitivity svg title");
if (!sensitivityTitle || !sensitivityTitle.includes("total_bounce_s") || !sensitivityTitle.includes("Sobol")) {
  await fail(`the sensitivity plot is not of total_bounce_s's Sobol' indices: "${sensitivityTitle}"`);
}
const sensitivityRows = await step("the sensitivity table lists the three parameters", async () => {
  await page.waitForFunction(() => document.querySelectorAll("#sensitivity-table tbody tr").length === 3);
  return page.$$eval("#sensitivity-table tbody tr td:first-child", (cells) => cells.map((c) => c.textContent));
});
if (!sensitivityRows.includes("impact_velocity_m_s")) await fail(`the sensitivity table lists ${sensitivityRows.join(", ")}`);
// Another metric, a device metric: the plot follows the selection.
await step("select final_radius_m for the sensitivity", () => page.selectOption("#sensitivity-metric", "final_radius_m"));
await step("the sensitivity plot follows the selection", () =>
  page.waitForFunction(() => {
    const title = document.querySelector("#plot-sensitivity svg title");
    return title && title.textContent.includes("final_radius_m");
  }),
);
if ((await page.textContent("#sensitivity-bin")).includes("wider than the devices' spread")) {
  await fail("#sensitivity-bin gives a reason the Result does not");
}
await page.waitForTimeout(300);
await step("save dashboard-sensitivity.png", () =>
  page.locator("#sensitivity-section").screenshot({ path: join(outDir, "dashboard-sensitivity.png") }),
);
log(`saved ${join(outDir, "dashboard-sensitivity.png")}`);
// A bin whose intervals include the sums' rounding says why, as the Result does: a scatter of
// 0.01 % puts the accumulated arc energy 1e4 standard deviations from a new device's 0.
const tightJob = await step("submit a sensitivity job of a tight scatter", () =>
  call("POST", "/v1/jobs", {
    scenario: { circuit: { supply_voltage_v: 48, current_a: 15 } },
    devices: 64,
    operations: 2,
    seed: 7,
    metrics: ["total_bounce_s", "cumulative_arc_energy_j"],
    scatter: [
      { parameter: "impact_velocity_m_s", per: "device", distribution: { kind: "lognormal", median: 3, sigma: 1e-4 } },
      { parameter: "static_force_n", per: "device", distribution: { kind: "lognormal", median: 0.5, sigma: 1e-4 } },
    ],
    sensitivity: { method: "sobol" },
  }),
);
await step(`the tight job ${tightJob.id} succeeds`, () => succeeds(tightJob.id));
const tightReason = (await call("GET", `/v1/jobs/${tightJob.id}/result`)).sensitivity.cumulative_arc_energy_j[0].reason;
if (!tightReason) await fail("the tight job's accumulated arc energy gives no reason");
await step(`open ${base}/jobs/${tightJob.id}`, () => page.goto(`${base}/jobs/${tightJob.id}`, { waitUntil: "load" }));
await step("select cumulative_arc_energy_j for the sensitivity", async () => {
  await page.waitForSelector("#sensitivity-section:not([hidden])");
  await page.selectOption("#sensitivity-metric", "cumulative_arc_energy_j");
});
await step("#sensitivity-bin gives the Result's reason", () =>
  page.waitForFunction((reason) => document.querySelector("#sensitivity-bin").textContent.includes(reason), tightReason),
);
// The Result's warnings are listed: here, Sobol' indices over fewer than 256 devices.
await step("#warnings lists the Result's warning at /devices", () =>
  page.waitForFunction(() => document.querySelector("#warnings-section:not([hidden])") &&
    document.querySelector("#warnings").textContent.includes("/devices")),
);

// Thresholds given as a list get a column each; one device shows no interval as if it bounded
// anything, and says why among the warnings; a name's bidirectional override is not written.
const listedJob = await step("submit a job of one device with listed thresholds", () =>
  call("POST", "/v1/jobs", {
    name: "One \u202edevice",
    devices: 1,
    operations: 20,
    seed: 3,
    limits: { e1: [{ above: 0.45 }, { below: 0.38 }] },
  }),
);
await step(`the listed job ${listedJob.id} succeeds`, () => succeeds(listedJob.id));
await step(`open ${base}/jobs/${listedJob.id}#metric=e1`, () =>
  page.goto(`${base}/jobs/${listedJob.id}#metric=e1`, { waitUntil: "load" }),
);
await step("the bins table heads a column per listed threshold", () =>
  page.waitForFunction(() => {
    const heads = [...document.querySelectorAll("#bins-table th")].map((h) => h.textContent);
    return heads.includes("P(above 0.45)") && heads.includes("P(below 0.38)");
  }),
);
await step("one device: said among the warnings, its intervals not shown", () =>
  page.waitForFunction(() =>
    document.querySelector("#warnings").textContent.includes("one device") &&
    document.querySelector("#devices-table").textContent.includes("– (one device)") &&
    !/\[[^\]]*\]/.test(document.querySelector("#devices-table").textContent)),
);
if ((await page.textContent("#job-name")) !== "One device") {
  await fail(`the job's name is written with its override: ${JSON.stringify(await page.textContent("#job-name"))}`);
}

// A job deleted while its page is open says so (the page looks every 15 s once the job ended).
await step(`open ${base}/jobs/${outsideJob.id}`, () => page.goto(`${base}/jobs/${outsideJob.id}`, { waitUntil: "load" }));
await step("its page says succeeded", () =>
  page.waitForFunction(() => document.querySelector("#job-status").textContent === "succeeded"),
);
await step("delete it through the API", () => call("DELETE", `/v1/jobs/${outsideJob.id}`));
await step("its page says deleted", () =>
  page.waitForFunction(() => document.querySelector("#job-status").textContent === "deleted", null, {
    timeout: 20_000,
    polling: 250,
  }),
);

log(`submitting ${ACTIVE_JOBS} long jobs`);
const active = [];
for (let k = 0; k < ACTIVE_JOBS; k++) {
  const job = await step(`submit long job ${k + 1}`, () =>
    // The first named by one unbroken word of 200 letters, which must wrap in the list.
    call("POST", "/v1/jobs", {
      name: k ? `Long job ${k + 1}` : "L".repeat(200), devices: 100000, operations: 10000, seed: k + 1,
    }),
  );
  active.push(job.id);
}

// Every event stream the jobs page opens, and when each plot request is answered.
const streams = [];
page.on("request", (request) => {
  const path = new URL(request.url()).pathname;
  if (path === "/v1/events" || /^\/v1\/jobs\/[^/]+\/events$/.test(path)) streams.push(path);
});
log(`opening ${base}/ with ${ACTIVE_JOBS} active jobs`);
const loadStarted = Date.now();
await step(`open ${base}/ under load`, () => page.goto(`${base}/`, { waitUntil: "load" }));
await step(`every trend plot loads within ${PLOT_TIMEOUT_MS / 1000} s`, () =>
  page.waitForFunction(
    () => {
      const plots = [...document.querySelectorAll("#schedules .plot")];
      return plots.length > 0 && plots.every((plot) => plot.querySelector("svg"));
    },
    null,
    { timeout: Math.max(1, PLOT_TIMEOUT_MS - (Date.now() - loadStarted)), polling: 100 },
  ),
);
log(`the trend plot loaded ${Date.now() - loadStarted} ms after navigation`);
const activeRows = await step(`the ${ACTIVE_JOBS} long jobs are listed as active`, async () => {
  await page.waitForFunction(
    (ids) => ids.every((id) => {
      const row = document.querySelector(`#jobs-body tr[data-job-id="${id}"]`);
      return row && ["queued", "running"].includes(row.dataset.status);
    }),
    active,
    { timeout: PLOT_TIMEOUT_MS },
  );
  return active.length;
});
const widths = await page.evaluate(() => [document.querySelector("#jobs-table").scrollWidth,
  document.querySelector("#jobs-section").clientWidth]);
if (widths[0] > widths[1]) {
  await fail(`a job's long name widens the list to ${widths[0]} px in a card of ${widths[1]} px`);
}
const nextRun = (await page.textContent(`[data-schedule-id="${schedule.id}"] .next-run`)) || "";
if (!/\d{4}-\d\d-\d\d \d\d:\d\d Europe\/Berlin \(\d{4}-\d\d-\d\d \d\d:\d\d UTC\)/.test(nextRun)) {
  await fail(`the schedule's next run does not name its zone: "${nextRun.trim()}"`);
}
if (streams.length !== 1 || streams[0] !== "/v1/events") {
  await fail(`the jobs page opened these event streams, not one /v1/events: ${streams.join(", ")}`);
}
log(`${activeRows} active rows on one event stream; ${nextRun.trim()}`);

log("submitting through the form while they run");
const submitStarted = Date.now();
const [loaded] = await step("submit the Quick check preset under load", () =>
  Promise.all([
    page.waitForResponse(
      (r) => new URL(r.url()).pathname === "/v1/jobs" && r.request().method() === "POST",
      { timeout: PLOT_TIMEOUT_MS },
    ),
    page.click("#submit-button"),
  ]),
);
if (loaded.status() !== 202) await fail(`POST /v1/jobs under load answered ${loaded.status()}`);
const formJob = await loaded.json();
active.push(formJob.id);
await step("the form says the job was submitted", () =>
  page.waitForSelector("#submit-ok:not([hidden])", { timeout: PLOT_TIMEOUT_MS }),
);
await step("its row appears", () =>
  page.waitForSelector(`#jobs-body tr[data-job-id="${formJob.id}"]`, { timeout: PLOT_TIMEOUT_MS }),
);
log(`submitted ${formJob.id} in ${Date.now() - submitStarted} ms`);

log(`opening ${base}${link} under load`);
const jobPageStarted = Date.now();
await step(`open ${base}${link} under load`, () => page.goto(`${base}${link}`, { waitUntil: "load" }));
await step(`the job page's plots load within ${PLOT_TIMEOUT_MS / 1000} s`, () =>
  page.waitForFunction(
    () => ["#plot-bands", "#plot-histograms"].every((id) => document.querySelector(`${id} svg`)),
    null,
    { timeout: Math.max(1, PLOT_TIMEOUT_MS - (Date.now() - jobPageStarted)), polling: 100 },
  ),
);
log(`the job page's plots loaded ${Date.now() - jobPageStarted} ms after navigation`);

await step("cancel the long jobs", () =>
  Promise.all(active.map((id) => call("DELETE", `/v1/jobs/${id}`).catch((error) => {
    if (!/ answered 409/.test(error.message)) throw error;
  }))),
);
await step("delete the schedule", () => call("DELETE", `/v1/schedules/${schedule.id}`));

if (pageErrors.length) await fail(`uncaught errors in the page: ${pageErrors.join(" | ")}`);
clearTimeout(watchdog);
await browser.close();
console.log("browser: 1 passed, 0 failed");
