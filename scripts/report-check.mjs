// Opens each report.html given on the command line in headless Chromium
// and checks what a colleague would see: no console error, no network
// request (every byte is in the file), the 3-D canvas draws the surface
// (pixels other than the white background), moving the time slider
// changes the picture, and each scene of the picker draws. Prints one
// JSON line per report (load time, size, pixels) and exits 1 on a failure.
// An argument `file::text` also checks that the page shows `text` as
// text, and every page that no script but its own ran (window.pwned is
// what the hostile names would set).
// Run by scripts/report-check.sh, which installs playwright-core.
import { chromium } from "playwright-core";
import { statSync } from "node:fs";
import { resolve } from "node:path";

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--disable-quic"],
});
let failed = 0;
for (const arg of process.argv.slice(2)) {
  const cut = arg.indexOf("::");
  const file = cut < 0 ? arg : arg.slice(0, cut);
  const literal = cut < 0 ? null : arg.slice(cut + 2);
  const page = await browser.newPage({ viewport: { width: 1200, height: 900 } });
  const errors = [], requests = [];
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("request", (r) => {
    const u = r.url();
    if (!/^(file|data|blob):/.test(u)) requests.push(u);
  });
  const start = Date.now();
  await page.goto("file://" + resolve(file));
  const viewer = await page.evaluate(() => !!document.getElementById("view"));
  const result = { file, bytes: statSync(file).size, viewer, problems: [] };
  const picture = () => page.evaluate(() => {
    const c = document.getElementById("view");
    const t = document.createElement("canvas");
    t.width = c.width; t.height = c.height;
    const x = t.getContext("2d");
    x.drawImage(c, 0, 0);
    const d = x.getImageData(0, 0, t.width, t.height).data;
    let drawn = 0, hash = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (d[i] < 245 || d[i + 1] < 245 || d[i + 2] < 245) drawn++;
      hash = (hash * 31 + d[i] + 7 * d[i + 1] + 13 * d[i + 2]) >>> 0;
    }
    return { drawn, hash };
  });
  const slide = (to) => page.evaluate((to) => {
    const s = document.getElementById("frame");
    s.value = to === "end" ? s.max : "0";
    s.dispatchEvent(new Event("input"));
    return !s.disabled;
  }, to);
  if (viewer) {
    let ready;
    try {
      ready = await page.evaluate(() => window.fshapeReport.ready);
    } catch (e) {
      ready = String(e);
    }
    result.load_ms = Date.now() - start;
    if (ready !== true) result.problems.push(`the 3-D view did not load: ${ready}`);
    const scenes = ready === true ? await page.evaluate(() => document.getElementById("scene").options.length) : 0;
    result.scenes = [];
    const mapHashes = new Map();
    for (let k = 0; k < scenes; k++) {
      await page.evaluate((k) => { const p = document.getElementById("scene"); p.value = String(k); p.dispatchEvent(new Event("change")); }, k);
      const first = await picture();
      const moves = await slide("end");
      const last = await picture();
      await slide("start");
      const name = await page.evaluate((k) => document.getElementById("scene").options[k].textContent, k);
      result.scenes.push({ name, drawn: first.drawn, changed: first.hash !== last.hash });
      // Scenes of several maps share one geometry: each must show its own map.
      const twin = mapHashes.get(first.hash);
      if (/channel|map \d/.test(name) && twin) result.problems.push(`${name}: draws the same picture as ${twin}`);
      if (/channel|map \d/.test(name)) mapHashes.set(first.hash, name);
      if (first.drawn < 500) result.problems.push(`${name}: the canvas is blank (${first.drawn} pixels drawn)`);
      if (moves && first.hash === last.hash) result.problems.push(`${name}: moving the slider did not change the picture`);
      if (scenes > 4 && k === 1) k = scenes - 2; // the first scenes and the last (a mode) are enough
    }
  } else {
    result.load_ms = Date.now() - start;
    const rows = await page.evaluate(() => document.querySelectorAll("table.sortable tbody tr").length);
    result.rows = rows;
    if (rows === 0) result.problems.push("the index has no rows");
    // Sorting by a header keeps every row.
    await page.click("table.sortable th:nth-child(4)");
    const after = await page.evaluate(() => document.querySelectorAll("table.sortable tbody tr").length);
    if (after !== rows) result.problems.push("sorting lost rows");
  }
  if (await page.evaluate(() => window.pwned !== undefined)) result.problems.push("a name in the page ran as a script");
  if (literal !== null) {
    result.literal = literal;
    if (!(await page.evaluate((t) => document.body.innerText.includes(t), literal))) {
      result.problems.push(`the page does not show ${JSON.stringify(literal)} as text`);
    }
  }
  if (errors.length) result.problems.push(...errors.map((e) => `console: ${e}`));
  if (requests.length) result.problems.push(...requests.map((u) => `network request: ${u}`));
  console.log(JSON.stringify(result));
  if (result.problems.length) failed++;
  await page.close();
}
await browser.close();
process.exit(failed ? 1 : 0);
