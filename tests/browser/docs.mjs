// The API's browsable documentation in a real browser (Debian's chromium, driven by
// playwright-core): /docs loads nothing from outside the server, throws no error, and shows the
// responses of every operation (RapiDoc left eight operations without theirs when a response
// example had a `null` member).
//
//   node tests/browser/docs.mjs BASE_URL
//
// Exits 0 on success; on a failure prints one line starting "docs test FAILED:" and exits 1.

import { chromium } from "playwright-core";

const base = (process.argv[2] || "").replace(/\/+$/, "");
if (!base) {
  console.error("usage: node docs.mjs BASE_URL");
  process.exit(2);
}
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";

const browser = await chromium.launch({ executablePath: CHROMIUM, args: ["--no-sandbox"] });
try {
  const page = await browser.newPage();
  const errors = [];
  const outside = [];
  page.on("pageerror", (error) => errors.push(String(error)));
  // A console error counts too (a missing /favicon.ico logged one).
  page.on("console", (message) => {
    if (message.type() === "error") errors.push(message.text());
  });
  page.on("request", (request) => {
    if (!request.url().startsWith(base)) outside.push(request.url());
  });
  await page.goto(`${base}/docs`, { waitUntil: "networkidle", timeout: 60_000 });
  // RapiDoc renders each operation's responses into its shadow DOM once the document is read.
  await page.waitForFunction(
    () => document.querySelector("rapi-doc")?.shadowRoot?.querySelectorAll("api-response").length > 0,
    null,
    { timeout: 60_000 },
  );
  const shown = await page.evaluate(() => {
    const responses = [...document.querySelector("rapi-doc").shadowRoot.querySelectorAll("api-response")];
    const text = (element) => (element.shadowRoot ? element.shadowRoot.textContent : element.textContent).trim();
    return { responses: responses.length, empty: responses.filter((r) => !text(r)).length };
  });
  const failures = [];
  if (errors.length) failures.push(`${errors.length} page errors, the first: ${errors[0]}`);
  if (outside.length) failures.push(`requests outside the server: ${outside.join(", ")}`);
  if (shown.empty) failures.push(`${shown.empty} of ${shown.responses} operations show no responses`);
  if (failures.length) {
    console.log(`docs test FAILED: ${failures.join("; ")}`);
    process.exitCode = 1;
  } else {
    console.log(`docs test passed: ${shown.responses} operations with their responses, nothing from outside`);
  }
} finally {
  await browser.close();
}
