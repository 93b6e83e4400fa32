// bouncewear dashboard: the jobs page (/) and the job page (/jobs/{id}). Plain JavaScript, no
// framework, nothing loaded from outside. Every API call goes through `api`, which adds
// `Authorization: Bearer KEY` when a key is stored; that is also why plots are fetched and injected
// rather than linked with <img src> (an image request cannot carry the header).
"use strict";

(() => {
  const KEY_STORAGE = "bouncewear.apiKey";
  const ACTIVE = new Set(["queued", "running"]);
  const STATUSES = ["queued", "running", "succeeded", "failed", "cancelled"];

  // ---------------------------------------------------------------------------------------------
  // API access
  // ---------------------------------------------------------------------------------------------

  function apiKey() {
    try {
      return (localStorage.getItem(KEY_STORAGE) || "").trim();
    } catch (_) {
      return "";
    }
  }

  function headers(extra) {
    const h = Object.assign({}, extra || {});
    const key = apiKey();
    if (key) h.Authorization = "Bearer " + key;
    return h;
  }

  /** An API error: the problem document (RFC 9457) when the server sent one. */
  class ApiError extends Error {
    constructor(status, problem, fallback) {
      const detail = (problem && (problem.detail || problem.title)) || fallback || "HTTP " + status;
      super(detail);
      this.status = status;
      this.problem = problem || null;
    }
  }

  function api(path, options) {
    const opts = Object.assign({}, options || {});
    opts.headers = headers(opts.headers);
    return fetch(path, opts);
  }

  async function problemOf(response) {
    const text = await response.text().catch(() => "");
    try {
      return JSON.parse(text);
    } catch (_) {
      // Not the server's problem document (a proxy's error page, say): its markup says nothing
      // readable, so the status stands alone.
      const markup = /^\s*</.test(text) || /html/i.test(response.headers.get("content-type") || "");
      return text && !markup ? { detail: text.slice(0, 300) } : null;
    }
  }

  async function failed(response) {
    const problem = await problemOf(response);
    let fallback = "HTTP " + response.status + (response.statusText ? " " + response.statusText : "");
    if (response.status === 401) fallback = "This server needs an API key: enter it at the top right.";
    const error = new ApiError(response.status, problem, fallback);
    if (response.status === 401) {
      error.message = apiKey()
        ? "The server did not accept this API key: check it at the top right."
        : "This server needs an API key: enter it at the top right.";
      keyRefused(Boolean(apiKey()));
    }
    return error;
  }

  /**
   * JSON.parse that keeps `seed` exact: seeds are u64 and above 2^53 a JS number would round them,
   * so an unsafe one becomes its source text (Chrome 114+ gives revivers the source; elsewhere it
   * is taken from the text when the text holds one seed only).
   */
  function parseJson(text) {
    // The reviver tripled the parse of a large Result (an outside probe: 11.6 MB, 123 -> 401 ms),
    // so it runs only where a seed needs it: one past 2^53 has 16 digits or more.
    if (!/"seed"\s*:\s*\d{16}/.test(text)) return JSON.parse(text);
    return JSON.parse(text, function (key, value, context) {
      if (key !== "seed" || typeof value !== "number" || Number.isSafeInteger(value)) return value;
      if (context && typeof context.source === "string") return context.source;
      const seeds = [...text.matchAll(/"seed"\s*:\s*(\d+)/g)];
      return seeds.length === 1 ? seeds[0][1] : value;
    });
  }

  async function getJson(path) {
    const response = await api(path, { headers: { Accept: "application/json" } });
    if (!response.ok) throw await failed(response);
    return parseJson(await response.text());
  }

  async function sendJson(method, path, body) {
    const init = { method, headers: { Accept: "application/json" } };
    if (body !== undefined) {
      init.headers["Content-Type"] = "application/json";
      init.body = typeof body === "string" ? body : JSON.stringify(body);
    }
    const response = await api(path, init);
    if (!response.ok) throw await failed(response);
    const text = await response.text();
    return text ? parseJson(text) : null;
  }

  // ---------------------------------------------------------------------------------------------
  // DOM helpers
  // ---------------------------------------------------------------------------------------------

  const $ = (selector, root) => (root || document).querySelector(selector);

  // Bidirectional embeddings, overrides and isolates (U+202A-U+202E, U+2066-U+2069) in a name
  // turn the text after them around (a schedule's run read its own timestamp backwards): the
  // page writes text without them, as the plots do.
  const BIDI_CONTROLS = /[\u202A-\u202E\u2066-\u2069]/g;
  function plain(text) {
    return String(text).replace(BIDI_CONTROLS, "");
  }

  /** `el("td", {class: "num"}, "text", child, ...)`. */
  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(attrs || {})) {
      if (value === undefined || value === null || value === false) continue;
      if (name === "class") node.className = value;
      else if (name === "text") node.textContent = plain(value);
      else if (name.startsWith("on") && typeof value === "function") node.addEventListener(name.slice(2), value);
      else node.setAttribute(name, value === true ? "" : plain(value));
    }
    for (const child of children.flat()) {
      if (child === undefined || child === null || child === false) continue;
      node.append(child instanceof Node ? child : document.createTextNode(plain(child)));
    }
    return node;
  }

  function show(node, visible) {
    if (node) node.hidden = !visible;
  }

  function setAlert(node, message) {
    if (!node) return;
    node.replaceChildren();
    if (message) node.append(message instanceof Node ? message : document.createTextNode(plain(message)));
    show(node, Boolean(message));
  }

  /** A number in at most 4 significant digits, exponent form when very small or large. */
  function fmt(value, digits) {
    const d = digits || 4;
    if (typeof value !== "number" || !Number.isFinite(value)) return "–";
    if (value === 0) return "0";
    const abs = Math.abs(value);
    if (abs >= 1e-3 && abs < 1e6) {
      // A value near 1 but not 1 (a probability of 0.99999) keeps the digits that tell it from 1.
      let shown = Number(value.toPrecision(d));
      for (let more = d + 1; Math.abs(shown) === 1 && shown !== value && more <= 15; more++) {
        shown = Number(value.toPrecision(more));
      }
      return String(shown);
    }
    return value.toExponential(d - 1).replace(/\.?0+e/, "e");
  }

  function fmtInterval(ci) {
    return Array.isArray(ci) && ci.length === 2 ? "[" + fmt(ci[0]) + ", " + fmt(ci[1]) + "]" : "–";
  }

  // A bin's operations, both ends included (its op_end is exclusive), as the plots head them.
  function opRange(bin) {
    return bin.op_start + "–" + Math.max(bin.op_start, bin.op_end - 1);
  }

  function fmtCount(value) {
    return typeof value === "number" && Number.isFinite(value) ? value.toLocaleString("en-US") : "–";
  }

  /** A time in the browser's zone, with the zone's name ("Nov 22, 2026, 16:05:12 CET"). */
  function fmtTime(text) {
    if (!text) return "–";
    const date = new Date(text);
    if (Number.isNaN(date.getTime())) return String(text);
    return date.toLocaleString(undefined, {
      year: "numeric", month: "short", day: "numeric", hour: "2-digit", minute: "2-digit", second: "2-digit",
      timeZoneName: "short",
    });
  }

  /** `YYYY-MM-DD HH:MM` of `date` in the IANA zone `timeZone`. */
  function wallClock(date, timeZone) {
    const parts = {};
    const format = new Intl.DateTimeFormat("en-GB", {
      timeZone, year: "numeric", month: "2-digit", day: "2-digit", hour: "2-digit", minute: "2-digit", hourCycle: "h23",
    });
    for (const part of format.formatToParts(date)) parts[part.type] = part.value;
    return parts.year + "-" + parts.month + "-" + parts.day + " " + parts.hour + ":" + parts.minute;
  }

  /**
   * A time in a schedule's zone, named, and in UTC: "2026-11-23 01:00 Europe/Berlin
   * (2026-11-23 00:00 UTC)". A zone this browser does not know is shown in UTC only.
   */
  function fmtZoned(text, timeZone) {
    if (!text) return "–";
    const date = new Date(text);
    if (Number.isNaN(date.getTime())) return String(text);
    const utc = wallClock(date, "UTC") + " UTC";
    if (!timeZone || timeZone === "UTC") return utc;
    try {
      return wallClock(date, timeZone) + " " + timeZone + " (" + utc + ")";
    } catch (_) {
      return utc;
    }
  }

  function badge(status) {
    const known = STATUSES.includes(status) ? status : "";
    return el("span", { class: "badge " + known }, status || "unknown");
  }

  function percent(progress) {
    const done = (progress && progress.operations_done) || 0;
    const total = (progress && progress.operations_total) || 0;
    return total > 0 ? Math.max(0, Math.min(100, (100 * done) / total)) : 0;
  }

  function progressBar(job, large) {
    const bar = el("div", {
      class: "progress" + (large ? " large" : ""),
      role: "progressbar", "aria-valuemin": "0", "aria-valuemax": "100", "aria-label": "progress",
    },
      el("div", { class: "track" }, el("div", { class: "fill" })),
      el("span", { class: "label" }));
    updateProgress(bar, job, large);
    return bar;
  }

  function updateProgress(bar, job, large) {
    if (!bar || !job) return;
    const status = job.status || "";
    const p = job.status === "succeeded" ? 100 : percent(job.progress);
    for (const s of STATUSES) bar.classList.toggle(s, s === status);
    $(".fill", bar).style.width = p.toFixed(1) + "%";
    const label = $(".label", bar);
    if (large && job.progress) {
      label.textContent = fmtCount(job.progress.operations_done) + " / " +
        fmtCount(job.progress.operations_total) + " operations (" + p.toFixed(0) + " %)";
    } else {
      label.textContent = p.toFixed(0) + " %";
    }
    bar.setAttribute("aria-valuenow", p.toFixed(0));
    bar.setAttribute("aria-valuetext", (status ? status + ", " : "") + label.textContent);
  }

  /**
   * Fetches an SVG plot (with the key) and puts it into `container`. The SVG is parsed as XML and
   * only an <svg> root is accepted; scripts and event attributes are dropped on the way in.
   */
  async function injectSvg(container, path) {
    if (!container) return;
    container.replaceChildren(el("div", { class: "placeholder" }, "Loading plot…"));
    try {
      const response = await api(path, { headers: { Accept: "image/svg+xml" } });
      if (!response.ok) throw await failed(response);
      const text = await response.text();
      const doc = new DOMParser().parseFromString(text, "image/svg+xml");
      const root = doc.documentElement;
      if (!root || root.nodeName.toLowerCase() !== "svg" || doc.querySelector("parsererror")) {
        throw new Error("the server did not send an SVG");
      }
      root.querySelectorAll("script, foreignObject").forEach((n) => n.remove());
      for (const node of [root, ...root.querySelectorAll("*")]) {
        for (const attr of [...node.attributes]) {
          if (/^on/i.test(attr.name) || /javascript:/i.test(attr.value)) node.removeAttribute(attr.name);
        }
      }
      container.replaceChildren(document.importNode(root, true));
    } catch (error) {
      container.replaceChildren(el("div", { class: "plot-error" }, "Plot unavailable: " + error.message));
    }
  }

  /** A link to an API resource that must carry the key: downloaded through fetch when a key is set. */
  function keyedLink(anchor, path, filename) {
    anchor.href = path;
    anchor.onclick = async (event) => {
      if (!apiKey()) return;
      event.preventDefault();
      try {
        const response = await api(path);
        if (!response.ok) throw await failed(response);
        const blob = await response.blob();
        const url = URL.createObjectURL(blob);
        const a = el("a", { href: url, download: filename });
        document.body.append(a);
        a.click();
        a.remove();
        setTimeout(() => URL.revokeObjectURL(url), 10000);
      } catch (error) {
        alert("Download failed: " + error.message);
      }
    };
  }

  /** The key field's note: "not accepted" once the server refused the stored key. */
  function keyRefused(refused) {
    const state = $("#api-key-state");
    if (state && refused) state.textContent = "not accepted";
  }

  function setupKeyField(onChange) {
    const input = $("#api-key");
    const state = $("#api-key-state");
    if (!input) return;
    input.value = apiKey();
    const label = () => {
      if (state) state.textContent = apiKey() ? "saved" : "";
    };
    label();
    input.addEventListener("change", () => {
      const value = input.value.trim();
      try {
        if (value) localStorage.setItem(KEY_STORAGE, value);
        else localStorage.removeItem(KEY_STORAGE);
      } catch (_) {
        // Private mode without storage: the key lives only as long as the page.
      }
      label();
      onChange();
    });
  }

  // ---------------------------------------------------------------------------------------------
  // Presets (docs/contract.md "Job")
  // ---------------------------------------------------------------------------------------------

  const SCATTER_RADIUS = {
    parameter: "contact_radius_m",
    per: "device",
    distribution: { kind: "normal", mean: 7.7e-3, sd: 0.8e-3, min: 1e-3 },
  };
  const SCATTER_VELOCITY = {
    parameter: "impact_velocity_m_s",
    per: "operation",
    distribution: { kind: "normal", mean: 0.224, sd: 0.02, min: 0.05 },
  };
  const AT_48V_15A = { circuit: { supply_voltage_v: 48, current_a: 15 } };

  const PRESETS = [
    {
      id: "quick",
      label: "Quick check: 100 devices x 100 operations, 48 V / 15 A",
      job: {
        name: "Quick check, 48 V / 15 A",
        devices: 100,
        operations: 100,
        scenario: AT_48V_15A,
        scatter: [SCATTER_RADIUS, SCATTER_VELOCITY],
      },
    },
    {
      id: "mechanical",
      label: "Paper rig, mechanical: 500 x 200",
      job: {
        name: "Paper rig, mechanical",
        devices: 500,
        operations: 200,
        scenario: {},
        scatter: [SCATTER_RADIUS, SCATTER_VELOCITY],
      },
    },
    {
      id: "wear",
      label: "Wear test 48 V / 15 A: 1000 x 1000 with failure criterion",
      job: {
        name: "Wear test 48 V / 15 A",
        devices: 1000,
        operations: 1000,
        scenario: AT_48V_15A,
        scatter: [SCATTER_RADIUS, SCATTER_VELOCITY],
        failure: { e1: { below: 0.3 } },
        limits: { total_bounce_s: 0.0095 },
      },
    },
    {
      id: "erosion",
      label: "Endurance with erosion limit: 500 x 2000, 48 V / 15 A",
      job: {
        name: "Endurance with erosion limit",
        devices: 500,
        operations: 2000,
        scenario: AT_48V_15A,
        scatter: [SCATTER_RADIUS, SCATTER_VELOCITY],
        failure: { eroded_mass_kg: { above: 2e-6 } },
      },
    },
  ];

  // ---------------------------------------------------------------------------------------------
  // The jobs page
  // ---------------------------------------------------------------------------------------------

  function parseEvent(block) {
    let event = "message";
    const data = [];
    for (const line of block.split(/\r?\n/)) {
      if (!line || line.startsWith(":")) continue;
      const colon = line.indexOf(":");
      const field = colon < 0 ? line : line.slice(0, colon);
      let value = colon < 0 ? "" : line.slice(colon + 1);
      if (value.startsWith(" ")) value = value.slice(1);
      if (field === "event") event = value;
      else if (field === "data") data.push(value);
    }
    return data.length ? { event, data: data.join("\n") } : null;
  }

  /**
   * Follows an event stream (`GET /v1/events` or `/v1/jobs/{id}/events`) with fetch (EventSource
   * cannot send the key header), calling onEvent(name, data) for each event while wanted() holds,
   * and onOpen() once the stream answered. Resolves true once onEvent returns true (or when no
   * longer wanted), false when the stream ends. `signal` aborts it.
   */
  async function streamEvents(path, onEvent, { wanted = () => true, onOpen = () => {}, signal } = {}) {
    const response = await api(path, { headers: { Accept: "text/event-stream" }, signal });
    if (!response.ok) throw await failed(response);
    onOpen();
    if (!response.body || !response.body.getReader) throw new Error("no streaming body");
    const reader = response.body.getReader();
    const decoder = new TextDecoder();
    let buffer = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (!wanted()) {
        reader.cancel().catch(() => {});
        return true;
      }
      if (done) return false;
      buffer += decoder.decode(value, { stream: true });
      let boundary;
      while ((boundary = buffer.search(/\r?\n\r?\n/)) >= 0) {
        const block = buffer.slice(0, boundary);
        buffer = buffer.slice(boundary).replace(/^\r?\n\r?\n/, "");
        const event = parseEvent(block);
        if (!event) continue;
        let data;
        try {
          data = parseJson(event.data);
        } catch (_) {
          continue;
        }
        if (onEvent(event.event, data)) {
          reader.cancel().catch(() => {});
          return true;
        }
      }
    }
  }

  function indexPage() {
    const body = $("#jobs-body");
    const rows = new Map(); // job id -> {row, bar, statusCell, job}
    let cursor = null;
    let pollTimer = null;
    let live = false; // the event stream is open: it brings every change to the rows
    let liveStream = null; // {generation, controller} of the current stream
    let keyRefused = false; // the server refused the key: nothing is polled until it changes
    let listed = false; // the first page came since the stream opened: a job not on it is judged
    const offPage = new Set(); // jobs the stream told of that belong to later pages

    // Live rows: one stream for all of the caller's jobs, however many run (a stream per job would
    // take the browser's six connections per host and stall the plots and the form). The rows are
    // (re)loaded once it answers, so that no job ending in between is missed. While it is down,
    // active rows are polled and it is retried.
    function followAll(retry) {
      if (liveStream) liveStream.controller.abort();
      const current = { controller: new AbortController() };
      liveStream = current;
      live = false;
      listed = false;
      keyRefused = false;
      let opened = false;
      let refused = false;
      streamEvents("/v1/events", (name, data) => {
        const entry = data && rows.get(data.id);
        if (!entry) {
          // Until the first page has come, it may well hold the job.
          const told = data && typeof data.id === "string" && name !== "deleted";
          if (told && listed && !offPage.has(data.id)) adopt(data.id, name === "status" ? data : null);
          return false;
        }
        if (name === "deleted") {
          removeRow(data.id);
        } else if (name === "status") {
          updateRow(data);
        } else if (name === "progress") {
          const progress = { operations_done: data.operations_done, operations_total: data.operations_total };
          updateRow(Object.assign({}, entry.job, { status: data.status || entry.job.status, progress }));
        }
        return false;
      }, {
        wanted: () => liveStream === current,
        signal: current.controller.signal,
        onOpen: () => {
          opened = true;
          live = true;
          // As many rows as were shown: pages loaded with "Load more" stay.
          loadJobs(false, rows.size);
        },
      })
        .catch((error) => {
          if (liveStream !== current) return;
          refused = error.status === 401;
          keyRefused = refused;
          if (!refused && !(error.status < 500)) {
            setAlert($("#jobs-error"), "Live updates stopped (" + error.message + "): trying again every 5 s.");
          }
        })
        .finally(() => {
          if (liveStream !== current) return;
          live = false;
          if (!opened && !retry) loadJobs(false);
          schedulePoll();
          // A refused key is tried again when the key changes, not every 5 s.
          if (refused) return;
          setTimeout(() => {
            if (liveStream === current) followAll(true);
          }, 5000);
        });
    }

    function jobRow(job) {
      const bar = progressBar(job, false);
      const statusCell = el("td", {}, badge(job.status));
      const row = el("tr", { "data-job-id": job.id, "data-status": job.status },
        el("td", { class: "name" }, job.name || el("span", { class: "muted" }, "(unnamed)")),
        el("td", { class: "nowrap" }, el("a", { href: "/jobs/" + encodeURIComponent(job.id), class: "mono" }, job.id)),
        statusCell,
        el("td", {}, bar),
        el("td", { class: "small nowrap" }, fmtTime(job.created_at)));
      return { row, bar, statusCell, job };
    }

    // A job the stream tells of that the list lacks: one submitted elsewhere (another tab, the
    // command line, a schedule) takes its place by creation, at the top for the newest; one older
    // than the oldest row, while later pages remain, belongs to one of them. The fetches of a
    // burst answer in any order, so a job is judged against the listed rows, never against one
    // adopted before it. The newest `status` told while it is fetched is the one shown.
    const adopting = new Map(); // job id -> its latest `status` resource, or null
    async function adopt(id, resource) {
      if (adopting.has(id)) {
        if (resource) adopting.set(id, resource);
        return;
      }
      adopting.set(id, resource);
      try {
        const job = resource || (await getJson("/v1/jobs/" + encodeURIComponent(id)));
        const oldest = body.lastElementChild && rows.get(body.lastElementChild.dataset.jobId);
        if (rows.has(id)) return;
        if (cursor && oldest && Date.parse(job.created_at) < Date.parse(oldest.job.created_at)) {
          offPage.add(id); // asked once: its later events are not fetched again
          return;
        }
        placeRow(adopting.get(id) || job);
      } catch (_) {
        // Deleted already, or the server is away: the next load lists what there is.
      } finally {
        adopting.delete(id);
      }
    }

    function removeRow(id) {
      const entry = rows.get(id);
      if (!entry) return;
      entry.row.remove();
      rows.delete(id);
      show($("#jobs-empty"), rows.size === 0);
    }

    function updateRow(job) {
      const entry = rows.get(job.id);
      if (!entry) return;
      entry.job = job;
      entry.row.dataset.status = job.status;
      entry.statusCell.replaceChildren(badge(job.status));
      updateProgress(entry.bar, job, false);
    }

    /** A row for a job not listed yet, before the first row created before it. */
    function placeRow(job) {
      if (rows.has(job.id)) {
        updateRow(job);
        return;
      }
      const created = Date.parse(job.created_at);
      const before = Array.from(body.children).find((row) => {
        const other = rows.get(row.dataset.jobId);
        return other && Date.parse(other.job.created_at) < created;
      });
      const entry = jobRow(job);
      rows.set(job.id, entry);
      entry.row.classList.add("fresh");
      body.insertBefore(entry.row, before || null);
      show($("#jobs-empty"), false);
      schedulePoll();
    }

    function addRows(jobs, atTop) {
      for (const job of jobs) {
        if (rows.has(job.id)) {
          updateRow(job);
          continue;
        }
        const entry = jobRow(job);
        rows.set(job.id, entry);
        if (atTop) {
          entry.row.classList.add("fresh");
          body.prepend(entry.row);
        } else {
          body.append(entry.row);
        }
      }
      show($("#jobs-empty"), rows.size === 0);
      schedulePoll();
    }

    // The latest load of the first page: the answer of one asked for before it is dropped (the
    // list loads at once and again when the event stream opens, in either order).
    let listing = 0;

    /** The first page (or, `more`, the next one), and further pages until `atLeast` rows show. */
    async function loadJobs(more, atLeast) {
      const page = (after) => getJson("/v1/jobs?limit=50" + (after ? "&cursor=" + encodeURIComponent(after) : ""));
      const generation = more ? listing : ++listing;
      try {
        let list = await page(more ? cursor : null);
        if (generation !== listing) return;
        if (!more) {
          rows.clear();
          offPage.clear();
          body.replaceChildren();
          listed = true;
        }
        addRows(list.jobs || [], false);
        cursor = list.next_cursor || null;
        while (cursor && rows.size < (atLeast || 0)) {
          list = await page(cursor);
          if (generation !== listing) return;
          addRows(list.jobs || [], false);
          cursor = list.next_cursor || null;
        }
        show($("#jobs-more"), Boolean(cursor));
        setAlert($("#jobs-error"), null);
      } catch (error) {
        if (generation !== listing) return;
        setAlert($("#jobs-error"), "Could not load the jobs: " + error.message);
        if (!more) {
          rows.clear();
          body.replaceChildren();
          show($("#jobs-empty"), false);
        }
      }
    }

    // Fallback while the event stream is down (a proxy, an error): active jobs are fetched every second.
    function schedulePoll() {
      if (pollTimer || keyRefused) return;
      const polled = (e) => ACTIVE.has(e.job.status) && !live;
      if (![...rows.values()].some(polled)) return;
      pollTimer = setTimeout(async () => {
        const ids = [...rows.values()].filter(polled).map((e) => e.job.id);
        await Promise.all(ids.map(async (id) => {
          try {
            updateRow(await getJson("/v1/jobs/" + encodeURIComponent(id)));
          } catch (_) {
            // A missed update is retried on the next tick.
          }
        }));
        pollTimer = null;
        schedulePoll();
      }, 1000);
    }

    // Submit form.
    const presetSelect = $("#preset");
    const textarea = $("#job-json");
    for (const preset of PRESETS) presetSelect.append(el("option", { value: preset.id }, preset.label));
    const fillPreset = () => {
      const preset = PRESETS.find((p) => p.id === presetSelect.value) || PRESETS[0];
      textarea.value = JSON.stringify(preset.job, null, 2);
      setAlert($("#submit-errors"), null);
    };
    presetSelect.addEventListener("change", fillPreset);
    $("#preset-reset").addEventListener("click", fillPreset);
    fillPreset();

    $("#submit-form").addEventListener("submit", async (event) => {
      event.preventDefault();
      const errors = $("#submit-errors");
      const ok = $("#submit-ok");
      setAlert(errors, null);
      show(ok, false);
      try {
        JSON.parse(textarea.value);
      } catch (error) {
        setAlert(errors, "The job is not valid JSON: " + error.message);
        return;
      }
      const button = $("#submit-button");
      button.disabled = true;
      $("#submit-state").textContent = "Submitting…";
      try {
        // The text as typed, not re-serialised: a seed above 2^53 must reach the server exactly.
        const created = await sendJson("POST", "/v1/jobs", textarea.value);
        addRows([created], true);
        ok.replaceChildren("Job submitted: ",
          el("a", { href: "/jobs/" + encodeURIComponent(created.id), class: "mono" }, created.id),
          " (" + created.status + ")");
        show(ok, true);
      } catch (error) {
        setAlert(errors, problemView(error));
      } finally {
        // Disabled while it was sent, the button lost the focus to the page: a keyboard user
        // would tab through every job to come back.
        const refocus = document.activeElement === document.body;
        button.disabled = false;
        if (refocus) button.focus();
        $("#submit-state").textContent = "";
      }
    });

    $("#jobs-refresh").addEventListener("click", () => loadJobs(false));
    $("#jobs-more").addEventListener("click", () => loadJobs(true));
    $("#schedules-refresh").addEventListener("click", () => loadSchedules());
    setupKeyField(() => {
      setAlert($("#submit-errors"), null);
      followAll();
      loadSchedules();
    });

    // Schedules.
    async function loadSchedules() {
      const list = $("#schedules");
      const error = $("#schedules-error");
      try {
        // Every page: a key holds at most --max-schedules-per-key (100 by default, one page).
        const schedules = [];
        let cursor = null;
        do {
          const data = await getJson("/v1/schedules" + (cursor ? "?cursor=" + encodeURIComponent(cursor) : ""));
          schedules.push(...(data.schedules || []));
          cursor = data.next_cursor || null;
        } while (cursor);
        setAlert(error, null);
        list.replaceChildren(...schedules.map(scheduleCard));
        show($("#schedules-empty"), schedules.length === 0);
      } catch (e) {
        list.replaceChildren();
        show($("#schedules-empty"), false);
        setAlert(error, e.status === 404 ? "This server has no schedules API." : "Could not load the schedules: " + e.message);
      }
    }

    function statisticName(s) {
      if (typeof s === "string") return s;
      if (s && typeof s === "object") return s.statistic || s.name || JSON.stringify(s);
      return String(s);
    }

    function scheduleCard(schedule) {
      const id = encodeURIComponent(schedule.id);
      const plot = el("div", { class: "plot", id: "trend-" + schedule.id });
      const note = el("div", { class: "run-note" });
      const statistics = (schedule.statistics || []).map(statisticName);
      const trendPath = (statistic) =>
        "/v1/schedules/" + id + "/plots/trend.svg" + (statistic ? "?statistic=" + encodeURIComponent(statistic) : "");
      let picker = null;
      if (statistics.length > 1) {
        picker = el("select", { "aria-label": "Statistic" }, statistics.map((s) => el("option", { value: s }, s)));
        picker.addEventListener("change", () => injectSvg(plot, trendPath(picker.value)));
      }
      const redraw = () => injectSvg(plot, trendPath(picker ? picker.value : null));
      // Once a run started here ends, its point joins the trend.
      const redrawWhenDone = (jobId) => {
        setTimeout(async () => {
          try {
            const job = await getJson("/v1/jobs/" + encodeURIComponent(jobId));
            if (ACTIVE.has(job.status)) redrawWhenDone(jobId);
            else redraw();
          } catch (_) {
            // Gone or no access: nothing to wait for.
          }
        }, 2000);
      };
      const runButton = el("button", { type: "button", class: "secondary" }, "Run now");
      runButton.addEventListener("click", async () => {
        runButton.disabled = true;
        note.replaceChildren("Starting…");
        note.className = "run-note muted";
        try {
          const created = await sendJson("POST", "/v1/schedules/" + id + "/run");
          const job = created && (created.job || created);
          note.className = "run-note";
          if (job && job.id) {
            note.replaceChildren("Started job ",
              el("a", { href: "/jobs/" + encodeURIComponent(job.id), class: "mono" }, job.id), ".");
            if (job.status) addRows([job], true);
            else loadJobs(false);
            redrawWhenDone(job.id);
          } else {
            note.replaceChildren("Started.");
            loadJobs(false);
          }
        } catch (error) {
          note.className = "run-note error-text";
          note.replaceChildren("Could not start a run: " + error.message);
        } finally {
          runButton.disabled = false;
        }
      });
      const card = el("article", { class: "schedule", "data-schedule-id": schedule.id },
        el("div", { class: "schedule-head" },
          el("h3", {}, schedule.name || schedule.id),
          el("span", { class: "badge " + (schedule.enabled ? "on" : "off") }, schedule.enabled ? "enabled" : "disabled"),
          el("span", { class: "spacer" }),
          picker,
          runButton),
        el("div", { class: "meta" },
          el("span", {}, el("code", {}, schedule.cron || "–"), " in ", el("b", {}, schedule.time_zone || "UTC")),
          el("span", { class: "next-run" }, "next run ", el("b", {}, schedule.enabled ? fmtZoned(schedule.next_run_at, schedule.time_zone) : "–")),
          el("span", {}, "last run ", el("b", {}, fmtZoned(schedule.last_run_at, schedule.time_zone))),
          schedule.skipped_runs ? el("span", {
            class: "skipped",
            title: schedule.last_skipped ? schedule.last_skipped.reason : "",
          }, "skipped ", el("b", {}, String(schedule.skipped_runs)),
            schedule.last_skipped ? [", last ", el("b", {}, fmtZoned(schedule.last_skipped.scheduled_for, schedule.time_zone)),
              ": " + schedule.last_skipped.reason] : null) : null,
          statistics.length ? el("span", {}, "follows ", el("b", {}, statistics.join(", "))) : null),
        plot,
        note);
      redraw();
      return card;
    }

    // The list at once, not only once the event stream answers (a proxy may hold a stream back).
    loadJobs(false);
    followAll();
    loadSchedules();
  }

  /** A refusal: its fields listed once each (a 422's `detail` joins the same list), or its detail. */
  function problemView(error) {
    const problem = error.problem;
    const errors = problem && Array.isArray(problem.errors) ? problem.errors : [];
    if (!errors.length) return el("div", {}, el("strong", {}, error.message || "Request failed"));
    return el("div", {},
      el("strong", {}, "The server refused the job (" + (problem.title || "HTTP " + error.status) + "):"),
      el("ul", {}, errors.map((e) =>
        el("li", {}, el("code", {}, e.pointer || "(document)"), ": ", e.detail || e.message || ""))));
  }

  // ---------------------------------------------------------------------------------------------
  // The job page
  // ---------------------------------------------------------------------------------------------

  function jobPage() {
    const segments = location.pathname.split("/").filter(Boolean);
    const id = decodeURIComponent(segments[segments.length - 1] || "");
    const base = "/v1/jobs/" + encodeURIComponent(id);
    const statusEl = $("#job-status");
    const bar = $("#job-progress");
    let job = null;
    let finished = false;
    let pollTimer = null;
    let resultLoaded = false;
    let following = 0; // generation of the current follow, so a key change restarts cleanly
    let cancelRefused = null; // why the last cancel was refused, while the job runs on

    document.title = "bouncewear · job " + id;
    $("#job-id").textContent = id;

    function setStatus(status) {
      statusEl.textContent = status;
      statusEl.className = "badge " + (STATUSES.includes(status) ? status : "");
      show($("#job-cancel"), ACTIVE.has(status));
    }

    function render(resource) {
      job = Object.assign({}, job || {}, resource);
      if (job.name) {
        $("#job-name").textContent = plain(job.name);
        document.title = "bouncewear · " + job.name;
      } else {
        $("#job-name").textContent = "Job";
      }
      setStatus(job.status);
      updateProgress(bar, job, true);
      const facts = [
        ["created", fmtTime(job.created_at)],
        ["started", fmtTime(job.started_at)],
        ["finished", fmtTime(job.finished_at)],
      ];
      if (job.seed !== undefined) facts.push(["seed", String(job.seed)]);
      $("#job-facts").replaceChildren(...facts.map(([k, v]) => el("div", {}, el("dt", {}, k), el("dd", {}, v))));
      if (job.status === "failed") {
        setAlert($("#job-error"), "The job failed: " + (job.error || "no reason given"));
      } else if (job.status === "cancelled") {
        setAlert($("#job-error"), "The job was cancelled" + (job.error ? ": " + job.error : "."));
      } else {
        // A refused cancel stays said while the job runs on (the next progress cleared it within
        // 100 ms, found from outside).
        setAlert($("#job-error"), ACTIVE.has(job.status) ? cancelRefused : null);
      }
      if (!ACTIVE.has(job.status)) {
        finished = true;
        if (job.status === "succeeded" && !resultLoaded) {
          resultLoaded = true;
          loadResult();
        }
      }
    }

    function onProgress(data) {
      // `progress` events carry only status and counts.
      render({
        status: data.status || (job && job.status),
        progress: { operations_done: data.operations_done, operations_total: data.operations_total },
      });
    }

    /** Follows the event stream; resolves true if it saw the final `status` event. */
    function followEvents(generation) {
      return streamEvents(
        base + "/events",
        (name, data) => {
          if (name === "status") render(data);
          else if (name === "progress") onProgress(data);
          return name === "status";
        },
        { wanted: () => generation === following },
      );
    }

    let answering = true; // the last look got an answer

    /** One look at the job; false once there is nothing more to look for (gone, or a refused key). */
    async function look() {
      try {
        render(await getJson(base));
        answering = true;
      } catch (error) {
        if (error.status === 404 || error.status === 401) {
          showLoadError(error);
          return false;
        }
        // Until the next answer (render clears it): the page is not silently stale.
        answering = false;
        setAlert($("#job-error"), "The server does not answer (" + error.message + "): trying again.");
      }
      return true;
    }

    /** The job's stream while it runs; a look a second while there is none, until it opens again. */
    async function follow(generation) {
      try {
        const ended = await followEvents(generation);
        if (ended || generation !== following) return;
      } catch (_) {
        // No stream (a proxy, an old server, a server restarting): poll until it is back.
      }
      if (generation === following && !finished) poll(generation);
    }

    function poll(generation) {
      clearTimeout(pollTimer);
      pollTimer = setTimeout(async () => {
        if (generation !== following) return;
        if (!(await look()) || finished) return;
        // The server answers again: back to its stream (a restart left the page polling).
        if (answering) follow(generation);
        else poll(generation);
      }, 1000);
    }

    // While the job runs, a look every 5 s beside the stream; once it ended, every 15 s, so that a
    // job deleted meanwhile does not stay on the page as if it were there; every 2 s while the
    // server does not answer, so that its return is seen soon.
    function watch(generation) {
      setTimeout(async () => {
        if (generation !== following) return;
        if (await look()) watch(generation);
      }, !answering ? 2000 : finished ? 15000 : 5000);
    }

    function showLoadError(error) {
      const gone = error.status === 404;
      // A job this page showed and the server no longer has was deleted.
      setStatus(gone ? (job ? "deleted" : "not found") : "unavailable");
      if (!gone) setAlert($("#job-error"), error.message);
      else if (job) setAlert($("#job-error"), "This job was deleted; what the page shows was loaded before.");
      else setAlert($("#job-error"), "No such job (for this API key).");
      if (gone) following += 1;
    }

    async function start() {
      following += 1;
      const generation = following;
      finished = false;
      // Nothing shown yet under this key: a 404 now is "not found", not "deleted"; and nothing
      // another key loaded stays on the page.
      job = null;
      cancelRefused = null;
      resultLoaded = false;
      show($("#result"), false);
      $("#job-name").textContent = "Job";
      document.title = "bouncewear · job " + id;
      $("#job-facts").replaceChildren();
      $("#compare-jobs").replaceChildren();
      compareAsked += 1; // a comparison on its way under the old key is dropped
      show($("#compare-result"), false);
      setAlert($("#compare-error"), null);
      clearTimeout(pollTimer);
      try {
        render(await getJson(base));
      } catch (error) {
        showLoadError(error);
        return;
      }
      // A slow poll beside the stream, in case a proxy buffers it (and, once the job ended, to see
      // it deleted).
      watch(generation);
      if (!finished) follow(generation);
    }

    $("#job-cancel").addEventListener("click", async () => {
      if (!confirm("Cancel this job?")) return;
      cancelRefused = null;
      try {
        const response = await api(base, { method: "DELETE" });
        if (!response.ok) throw await failed(response);
        const text = await response.text();
        if (text) {
          try {
            render(parseJson(text));
          } catch (_) {
            // Not a job resource: the stream or the poll brings the new status.
          }
        }
      } catch (error) {
        cancelRefused = "Could not cancel: " + error.message;
        setAlert($("#job-error"), cancelRefused);
      }
    });

    // The result.
    async function loadResult(attempt) {
      let result;
      try {
        result = await getJson(base + "/result");
      } catch (error) {
        // 409 right after the status changed: the result may still be on its way.
        if (error.status === 409 && (attempt || 0) < 5) {
          setTimeout(() => loadResult((attempt || 0) + 1), 1000);
          return;
        }
        resultLoaded = false;
        setAlert($("#job-error"), "Could not load the result: " + error.message);
        return;
      }
      show($("#result"), true);
      const job = result.job || {};
      // One device is one group: no spread between groups to measure, so every interval is its
      // point (the contract), and none is shown as if it bounded anything.
      pointIntervals = (typeof job.devices_run === "number" ? job.devices_run : job.devices) === 1;
      renderWarnings(result);
      renderOperations(result);
      renderLife(result);
      renderSensitivity(result);
      renderRareEvent(result);
      renderDevices(result);
      renderRun(result);
      setupCompare();
    }

    function renderOperations(result) {
      const select = $("#metric");
      const metrics = Object.keys(result.operations || {});
      select.replaceChildren(...metrics.map((m) => el("option", { value: m }, m)));
      if (!metrics.length) {
        $("#plot-bands").replaceChildren(el("div", { class: "placeholder" }, "No operation metrics in this result."));
        $("#plot-histograms").replaceChildren();
        return;
      }
      const wanted = new URLSearchParams(location.hash.slice(1)).get("metric");
      select.value = metrics.includes(wanted) ? wanted
        : metrics.includes("total_bounce_s") ? "total_bounce_s" : metrics[0];
      const showMetric = () => {
        const metric = select.value;
        const q = "?metric=" + encodeURIComponent(metric);
        injectSvg($("#plot-bands"), base + "/plots/bands.svg" + q);
        injectSvg($("#plot-histograms"), base + "/plots/histograms.svg" + q);
        renderBins(result.operations[metric] || []);
        // The address keeps what else it links (#compare=ID), and a comparison follows the metric.
        const hash = new URLSearchParams(location.hash.slice(1));
        hash.set("metric", metric);
        history.replaceState(null, "", "#" + hash.toString());
        const comparing = hash.get("compare");
        if (comparing && compareReady) compareWith(comparing);
      };
      select.onchange = showMetric;
      showMetric();
    }

    // The job ran one device: its intervals are points and are not shown (see loadResult).
    let pointIntervals = false;

    function interval(ci) {
      return pointIntervals ? "– (one device)" : fmtInterval(ci);
    }

    /** The Result's warnings (`diagnostics`), each with the field of the job it concerns. */
    function renderWarnings(result) {
      const warnings = Array.isArray(result.diagnostics) ? result.diagnostics.slice() : [];
      if (pointIntervals) {
        warnings.push({ pointer: "/devices", detail: "one device: there is no spread between devices to " +
          "measure, so no interval is shown and no quantile is bounded; run two devices or more for intervals" });
      }
      show($("#warnings-section"), warnings.length > 0);
      $("#warnings").replaceChildren(...warnings.map((w) =>
        el("li", {}, el("code", {}, w.pointer || "(job)"), ": ", w.detail || "")));
    }

    /**
     * A quantile's value; where the data cannot bound its level it is marked, with the reason on
     * hover, and `marked` is told, so that the table's note can say what the mark means.
     */
    function quantileCell(summary, key, marked) {
      const quantile = summary.quantiles && summary.quantiles[key];
      if (!quantile) return el("td", { class: "num" }, "–");
      if (typeof quantile.reason !== "string") return el("td", { class: "num" }, fmt(quantile.value));
      marked();
      return el("td", { class: "num unbounded", title: quantile.reason }, fmt(quantile.value) + " *");
    }

    function showUnboundedNote(node, shown) {
      node.textContent = shown ? "* The data cannot bound this quantile's level (hover over it for why): " +
        "its value is the sample's, and a decision should not rest on it." : "";
      show(node, shown);
    }

    function renderBins(bins) {
      // A number as the limit (`exceedance`), or a list of thresholds above or below
      // (`exceedances`, one column each in the list's order).
      const single = bins.find((b) => b.exceedance);
      const listed = ((bins.find((b) => Array.isArray(b.exceedances)) || {}).exceedances || [])
        .map((t) => (typeof t.above === "number" ? "above " + fmt(t.above) : "below " + fmt(t.below)));
      const heads = ["operations", "n", "mean", "p05", "p50", "p95", "max",
        ...(single ? ["P(above " + fmt(single.exceedance.limit) + ")"] : []),
        ...listed.map((h) => "P(" + h + ")")];
      const head = el("tr", {}, heads.map((h, i) => el("th", { class: i ? "num" : "" }, h)));
      const probability = (e) => el("td", { class: "num" }, e ? fmt(e.probability) + " " + interval(e.ci95) : "–");
      let unbounded = false;
      const marked = () => { unbounded = true; };
      const rowsHtml = bins.map((b) => el("tr", {},
        el("td", {}, opRange(b)),
        el("td", { class: "num" }, fmtCount(b.n)),
        el("td", { class: "num" }, fmt(b.mean)),
        quantileCell(b, "p05", marked),
        quantileCell(b, "p50", marked),
        quantileCell(b, "p95", marked),
        el("td", { class: "num" }, fmt(b.max)),
        single ? probability(b.exceedance) : null,
        listed.map((_, i) => probability((b.exceedances || [])[i]))));
      $("#bins-table").replaceChildren(el("thead", {}, head), el("tbody", {}, rowsHtml));
      showUnboundedNote($("#bins-note"), unbounded);
    }

    function renderLife(result) {
      const life = result.life;
      show($("#life-section"), Boolean(life));
      if (!life) return;
      const analysis = life.analysis || {};
      const criteria = Object.entries(life.criteria || {}).map(([metric, c]) =>
        metric + (c.above !== undefined ? " above " + fmt(c.above) : "") + (c.below !== undefined ? " below " + fmt(c.below) : ""));
      const failures = life.failures !== undefined ? life.failures : analysis.failures;
      const censored = life.censored !== undefined ? life.censored : analysis.censored;
      $("#life-criteria").textContent = (criteria.length ? "A device fails at its first operation with " + criteria.join(" or ") + ". " : "") +
        fmtCount(failures) + " failed, " + fmtCount(censored) + " survived the test (right-censored).";
      injectSvg($("#plot-weibull"), base + "/plots/weibull.svg");
      keyedLink($("#life-csv"), base + "/life?format=csv", "job-" + id + "-life.csv");

      renderFits(analysis);
      const w = analysis.weibull;
      const rows = [];
      if (w) {
        rows.push(["β (shape)", fmt(w.beta), fmtInterval(w.beta_ci95)]);
        rows.push(["η (scale), operations", fmt(w.eta), fmtInterval(w.eta_ci95)]);
      }
      for (const [label, b] of [["B1, operations", analysis.b1], ["B10, operations", analysis.b10]]) {
        if (b) rows.push([label + " (Fisher bounds)", fmt(b.value), fmtInterval(b.ci95)]);
        if (b && b.lr_ci95) rows.push([label + " (likelihood-ratio bounds)", fmt(b.value), fmtInterval(b.lr_ci95)]);
      }
      // Read off the Kaplan-Meier curve, no distribution assumed (with or without a fit); a
      // bound past the test is open.
      for (const [label, b] of [["B1, operations", analysis.b1_observed], ["B10, operations", analysis.b10_observed]]) {
        if (!b) continue;
        const end = (x) => (x === null || x === undefined ? "past the test" : fmt(x));
        rows.push([label + " (Kaplan-Meier, no model)", end(b.value), "[" + end(b.ci95[0]) + ", " + end(b.ci95[1]) + "]"]);
      }
      const body = rows.map(([k, v, ci]) => el("tr", {}, el("td", {}, k), el("td", { class: "num" }, v), el("td", { class: "num" }, ci)));
      if (!w) {
        body.unshift(el("tr", {}, el("td", { class: "error-text", colspan: "3" },
          "No Weibull fit: " + (analysis.weibull_error || "not available"))));
      }
      $("#life-table").replaceChildren(
        el("thead", {}, el("tr", {}, el("th", {}, "Weibull fit and B-lives"), el("th", { class: "num" }, "estimate"), el("th", { class: "num" }, "95 % interval"))),
        el("tbody", {}, body));
    }

    // The candidate distributions, best first by AICc, with BIC and Anderson-Darling.
    function renderFits(analysis) {
      const fits = analysis.fits || [];
      $("#fit-warning").textContent = analysis.fit_warning ? "Note: " + analysis.fit_warning : "";
      if (!fits.length) {
        $("#fits-table").replaceChildren();
        return;
      }
      const parameters = (f) => Object.entries(f.parameters || {}).map(([k, v]) => k + " = " + fmt(v)).join(", ");
      $("#fits-table").replaceChildren(
        el("thead", {}, el("tr", {}, ["distribution (best first)", "parameters", "AICc", "BIC", "Anderson-Darling"]
          .map((h, i) => el("th", { class: i > 1 ? "num" : "" }, h)))),
        el("tbody", {}, fits.map((f) => el("tr", {},
          el("td", {}, f.distribution),
          el("td", { class: "small" }, parameters(f)),
          el("td", { class: "num" }, fmt(f.aicc, 6)),
          el("td", { class: "num" }, fmt(f.bic, 6)),
          el("td", { class: "num" }, fmt(f.anderson_darling))))));
    }

    // A rare event: its probability with interval, the tail curve and the design point.
    function renderRareEvent(result) {
      const rare = result.rare_event;
      show($("#rare-section"), Boolean(rare));
      if (!rare) return;
      const asked = (result.job && result.job.rare_event) || {};
      // The threshold as asked, every digit: rounded it would misstate the question.
      const side = asked.below !== undefined ? "below " + String(asked.below) : "above " + String(asked.above);
      $("#rare-question").textContent = "P(" + asked.metric + " " + side + ") per device: " + fmt(rare.probability) +
        ", 95 % interval " + fmtInterval(rare.ci95) + (typeof rare.cov === "number" ? ", c.o.v. " + fmt(rare.cov, 2) : "") +
        "; " + rare.method + ", " + fmtCount(rare.evaluations) + " evaluations" +
        (typeof rare.beta === "number" ? ", β = " + fmt(rare.beta, 3) : "") + ".";
      injectSvg($("#plot-tail"), base + "/plots/tail.svg");
      const entries = Object.entries(rare.design_point || {});
      $("#rare-table").replaceChildren(
        el("thead", {}, el("tr", {}, el("th", {}, "Design point (most probable failing inputs)"), el("th", { class: "num" }, "value"))),
        el("tbody", {}, entries.length
          ? entries.slice(0, 40).map(([k, v]) => el("tr", {}, el("td", {}, k), el("td", { class: "num" }, fmt(v))))
          : [el("tr", {}, el("td", { class: "muted" }, "No evaluated input reached the threshold."))]));
    }

    // Which parameters drive each metric: the plot of the first and last bin, and a table of the
    // last bin's indices (method regression: its standardised regression coefficients).
    function renderSensitivity(result) {
      const sensitivity = result.sensitivity;
      const metrics = Object.keys(sensitivity || {});
      show($("#sensitivity-section"), metrics.length > 0);
      if (!metrics.length) return;
      const select = $("#sensitivity-metric");
      select.replaceChildren(...metrics.map((m) => el("option", { value: m }, m)));
      const operationMetric = $("#metric").value;
      select.value = metrics.includes(operationMetric) ? operationMetric
        : metrics.includes("total_bounce_s") ? "total_bounce_s" : metrics[0];
      const showMetric = () => {
        const metric = select.value;
        injectSvg($("#plot-sensitivity"), base + "/plots/sensitivity.svg?metric=" + encodeURIComponent(metric));
        renderSensitivityTable(sensitivity[metric] || []);
      };
      select.onchange = showMetric;
      showMetric();
    }

    function renderSensitivityTable(bins) {
      const table = $("#sensitivity-table");
      const last = bins[bins.length - 1];
      const entries = Object.entries((last && last.indices) || {});
      if (!entries.length) {
        $("#sensitivity-bin").textContent = "";
        table.replaceChildren(el("tbody", {}, el("tr", {}, el("td", { class: "muted" }, "No indices for this metric."))));
        return;
      }
      const sobol = entries.some(([, p]) => p.first || p.total);
      const where = typeof last.op_start === "number" && typeof last.op_end === "number"
        ? "Last bin, operations " + opRange(last)
        : "Over the devices at the end of the test";
      // The reason says itself what it is about (the sums' rounding, every index unknown, one
      // device): it is quoted as it stands.
      const reason = typeof last.reason === "string" && last.reason ? " Note: " + last.reason + "." : "";
      $("#sensitivity-bin").textContent = plain(where +
        (typeof last.r_squared === "number" ? "; the regression explains R² = " + fmt(last.r_squared, 3) + " of the variance." : ".") +
        reason);
      const weight = (p) => {
        const v = sobol ? (p.total || {}).value : Math.abs(p.src);
        return typeof v === "number" && Number.isFinite(v) ? v : -Infinity;
      };
      entries.sort(([, a], [, b]) => (weight(b) - weight(a)) || 0);
      const index = (e) => [
        el("td", { class: "num" }, e ? fmt(e.value, 3) : "–"),
        el("td", { class: "num" }, e ? interval(e.ci95) : "–"),
      ];
      const heads = sobol
        ? ["parameter", "per", "first-order", "95 % interval", "total", "95 % interval"]
        : ["parameter", "per", "standardised regression coefficient"];
      table.replaceChildren(
        el("thead", {}, el("tr", {}, heads.map((h, i) => el("th", { class: i > 1 ? "num" : "" }, h)))),
        el("tbody", {}, entries.map(([name, p]) => el("tr", {},
          el("td", { class: "mono" }, name),
          el("td", {}, p.per || "–"),
          sobol ? [...index(p.first), ...index(p.total)] : el("td", { class: "num" }, fmt(p.src, 3))))));
    }

    function renderDevices(result) {
      const devices = result.devices || {};
      const names = Object.keys(devices);
      const table = $("#devices-table");
      if (!names.length) {
        table.replaceChildren(el("tbody", {}, el("tr", {}, el("td", { class: "muted" }, "No device metrics in this result."))));
        return;
      }
      let unbounded = false;
      const marked = () => { unbounded = true; };
      table.replaceChildren(
        el("thead", {}, el("tr", {}, ["metric", "mean", "mean 95 % CI", "p05", "p50", "p95"].map((h, i) => el("th", { class: i ? "num" : "" }, h)))),
        el("tbody", {}, names.map((name) => {
          const s = devices[name] || {};
          return el("tr", {},
            el("td", { class: "mono" }, name),
            el("td", { class: "num" }, fmt(s.mean)),
            el("td", { class: "num" }, interval(s.mean_ci95)),
            quantileCell(s, "p05", marked),
            quantileCell(s, "p50", marked),
            quantileCell(s, "p95", marked));
        })));
      showUnboundedNote($("#devices-note"), unbounded);
    }

    // Comparing this job (design a) with another succeeded one (design b), linkable as
    // #compare=ID; a change of metric compares again once the form is set up.
    let compareReady = false;
    // The comparisons asked for, counted: only the latest's answer is shown (an earlier one that
    // came late showed, and wrote its job back into an address the user had left).
    let compareAsked = 0;
    function setupCompare() {
      compareReady = true;
      const form = $("#compare-form");
      const input = $("#compare-with");
      getJson("/v1/jobs?limit=100").then((page) => {
        const options = (page.jobs || []).filter((j) => j.id !== id && j.status === "succeeded")
          .map((j) => el("option", { value: j.id }, j.name || j.id));
        $("#compare-jobs").replaceChildren(...options);
      }).catch(() => {});
      form.onsubmit = (event) => {
        event.preventDefault();
        const other = input.value.trim();
        if (other) compareWith(other);
      };
      const wanted = new URLSearchParams(location.hash.slice(1)).get("compare");
      if (wanted) {
        input.value = wanted;
        compareWith(wanted);
      }
      // An address changed in place (a link followed, a hash typed) shows what it names: its
      // metric (which compares again) and its comparison, or none.
      window.onhashchange = () => {
        const hash = new URLSearchParams(location.hash.slice(1));
        const select = $("#metric");
        const [metric, other] = [hash.get("metric"), hash.get("compare")];
        input.value = other || "";
        if (!other) {
          // Nothing compared: an answer still on its way is dropped, an old error cleared.
          compareAsked += 1;
          show($("#compare-result"), false);
          setAlert($("#compare-error"), null);
        }
        const known = [...select.options].some((o) => o.value === metric);
        if (metric && metric !== select.value && known) {
          select.value = metric;
          select.onchange(); // shows the metric, and compares again for it
          return;
        }
        if (metric && !known) {
          // A metric the job lacks: the address says what is shown, as on load.
          hash.set("metric", select.value);
          history.replaceState(null, "", "#" + hash.toString());
        }
        if (other) compareWith(other);
      };
    }

    async function compareWith(other) {
      const asked = ++compareAsked;
      const metric = $("#metric").value || "total_bounce_s";
      const path = base + "/compare/" + encodeURIComponent(other);
      const query = "?metric=" + encodeURIComponent(metric);
      let comparison;
      try {
        comparison = await getJson(path + query + "&statistics=mean,p50,p95");
      } catch (error) {
        if (asked !== compareAsked) return;
        show($("#compare-result"), false);
        setAlert($("#compare-error"), "Could not compare: " + error.message);
        return;
      }
      if (asked !== compareAsked) return;
      setAlert($("#compare-error"), null);
      show($("#compare-result"), true);
      const hash = new URLSearchParams(location.hash.slice(1));
      hash.set("compare", other);
      history.replaceState(null, "", "#" + hash.toString());
      injectSvg($("#plot-compare-bands"), path + "/plots/bands.svg" + query);
      const both = (d) => [fmt(d.a), fmt(d.b), fmt(d.difference) + " " + fmtInterval(d.difference_ci95),
        d.ratio === null || d.ratio === undefined ? "–" : fmt(d.ratio, 4) + " " + fmtInterval(d.ratio_ci95)];
      const head = (first) => el("thead", {}, el("tr", {}, [first, "a", "b", "a − b (95 %)", "a / b (95 %)"]
        .map((h, i) => el("th", { class: i ? "num" : "" }, h))));
      const rows = [];
      for (const bin of comparison.bins || []) {
        for (const [name, d] of Object.entries(bin.statistics || {})) {
          rows.push(el("tr", {}, el("td", {}, "ops " + opRange(bin) + ": " + name),
            ...both(d).map((v) => el("td", { class: "num" }, v))));
        }
      }
      $("#compare-table").replaceChildren(head(comparison.metric), el("tbody", {}, rows));
      const life = comparison.life;
      show($("#plot-compare-weibull"), Boolean(life));
      if (life) {
        injectSvg($("#plot-compare-weibull"), path + "/plots/weibull.svg");
        const lifeRows = (life.b_lives || []).map((b) => el("tr", {},
          el("td", {}, "B" + fmt(100 * b.p) + ", operations (Weibull)"), ...both(b).map((v) => el("td", { class: "num" }, v))));
        for (const b of life.b_lives_observed || []) {
          lifeRows.push(el("tr", {}, el("td", {}, "B" + fmt(100 * b.p) + ", operations (Kaplan-Meier)"),
            ...both(b).map((v) => el("td", { class: "num" }, v))));
        }
        const o = life.outlasts || {};
        const modelled = o.weibull === null || o.weibull === undefined ? "–"
          : fmt(o.weibull, 4) + " " + fmtInterval(o.weibull_ci95);
        lifeRows.push(el("tr", {}, el("td", {}, "P(a device of a outlasts one of b)"),
          el("td", { class: "num", colspan: "2" }, "Weibull fits: " + modelled),
          el("td", { class: "num", colspan: "2" }, "simulated pairs: " + fmtInterval(o.observed) +
            (o.observed_ci95 ? ", 95 % interval " + fmtInterval(o.observed_ci95) : ""))));
        $("#compare-life-table").replaceChildren(head("life"), el("tbody", {}, lifeRows));
      } else {
        $("#compare-life-table").replaceChildren();
      }
      const notes = [...(comparison.notes || []), ...((comparison.life || {}).notes || [])];
      $("#compare-notes").replaceChildren(...notes.map((n) => el("li", {}, n)));
    }

    function renderRun(result) {
      const j = result.job || {};
      const t = result.timing || {};
      // With a precision target `devices` is a batch's size; `devices_run` the devices it took.
      const ran = typeof j.devices_run === "number" ? j.devices_run : j.devices;
      const facts = [
        ["devices", fmtCount(ran) + (ran !== j.devices ? " (batches of " + fmtCount(j.devices) + ")" : "")],
        ["operations", fmtCount(j.operations)],
        ["bin", fmtCount(j.bin_operations) + " ops"],
        ["fidelity", j.fidelity || "–"],
        ["sampler", j.sampler || "–"],
        ["seed", j.seed !== undefined ? String(j.seed) : "–"],
        ["wall time", typeof t.wall_s === "number" ? fmt(t.wall_s, 3) + " s" : "–"],
        ["throughput", typeof t.operations_per_s === "number" ? fmt(t.operations_per_s / 1e6, 3) + " M op/s" : "–"],
      ];
      if (result.precision) {
        const p = result.precision;
        facts.push(["precision", (p.met ? "met" : "not met") + ": ±" + fmt(100 * p.achieved_relative_half_width, 2) +
          " % of " + p.statistic + " " + p.metric]);
      }
      $("#run-facts").replaceChildren(...facts.map(([k, v]) => el("div", {}, el("dt", {}, k), el("dd", {}, v))));
      keyedLink($("#result-json"), base + "/result", "job-" + id + "-result.json");
    }

    setupKeyField(start);
    start();
  }

  document.addEventListener("DOMContentLoaded", () => {
    const page = document.body.dataset.page;
    if (page === "index") indexPage();
    else if (page === "job") jobPage();
  });
})();
