// End-to-end test of the dashboard in a real browser (Debian's chromium, driven by playwright-core):
// submit the "Quick check" preset on /, follow the job to `succeeded` on its page, check that the
// wear-curve and histogram plots are there, and save screenshots.
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
const OVERALL_TIMEOUT_MS = 240_000;

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

if (pageErrors.length) await fail(`uncaught errors in the page: ${pageErrors.join(" | ")}`);
clearTimeout(watchdog);
await browser.close();
console.log("browser: 1 passed, 0 failed");
