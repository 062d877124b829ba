// Loads a mission's report.html from file:// in headless Chromium (Debian's /usr/bin/chromium,
// driven by npm `playwright-core`; nothing is downloaded) and checks that
//   1. the page loads with no console error and no uncaught exception;
//   2. every 3D view draws: the viewer's own read-back (window.scarpViewerStats) and a PNG
//      screenshot of the first canvas, decoded here, both show enough non-background pixels
//      and contrast;
//   3. the toggles work: the ground-truth layer and the error colouring change the pixels.
// Writes the screenshot and a JSON of the statistics into the output folder.
//
//   node .ci/report_browser_test.mjs out/simulate/report.html .ci/out
import { mkdirSync, mkdtempSync, writeFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { inflateSync } from 'node:zlib';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
const { chromium } = require('playwright-core');

const [reportPath, outDir = '.ci/out'] = process.argv.slice(2);
if (!reportPath) {
  console.error('usage: node report_browser_test.mjs REPORT.html [OUT_DIR]');
  process.exit(2);
}
mkdirSync(outDir, { recursive: true });

/** Decodes an 8-bit RGB or RGBA, non-interlaced PNG into {width, height, channels, pixels}. */
function decodePng(buf) {
  let pos = 8;
  let width = 0;
  let height = 0;
  let colorType = 0;
  const idat = [];
  while (pos < buf.length) {
    const len = buf.readUInt32BE(pos);
    const type = buf.toString('latin1', pos + 4, pos + 8);
    const data = buf.subarray(pos + 8, pos + 8 + len);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      if (data[8] !== 8 || data[12] !== 0) throw new Error('only 8-bit non-interlaced PNGs');
      colorType = data[9];
    } else if (type === 'IDAT') {
      idat.push(data);
    }
    pos += 12 + len;
  }
  const channels = { 2: 3, 6: 4 }[colorType];
  if (!channels) throw new Error(`PNG colour type ${colorType} not handled`);
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const pixels = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= channels ? pixels[y * stride + x - channels] : 0;
      const b = y > 0 ? pixels[(y - 1) * stride + x] : 0;
      const c = x >= channels && y > 0 ? pixels[(y - 1) * stride + x - channels] : 0;
      let v = line[x];
      if (filter === 1) v += a;
      else if (filter === 2) v += b;
      else if (filter === 3) v += (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c;
        const pa = Math.abs(p - a);
        const pb = Math.abs(p - b);
        const pc = Math.abs(p - c);
        v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      }
      pixels[y * stride + x] = v & 255;
    }
  }
  return { width, height, channels, pixels };
}

function pixelStats({ width, height, channels, pixels }, background = [0xf7, 0xf7, 0xf7]) {
  let differ = 0;
  let sum = 0;
  let sum2 = 0;
  const colours = new Set();
  for (let i = 0; i < width * height; i++) {
    const [r, g, b] = [pixels[i * channels], pixels[i * channels + 1], pixels[i * channels + 2]];
    if (Math.abs(r - background[0]) + Math.abs(g - background[1]) + Math.abs(b - background[2]) > 24) differ++;
    const y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    sum += y;
    sum2 += y * y;
    colours.add(((r >> 4) << 8) | ((g >> 4) << 4) | (b >> 4));
  }
  const mean = sum / (width * height);
  return {
    width,
    height,
    nonBackgroundFraction: differ / (width * height),
    distinctColours: colours.size,
    meanLuma: mean,
    stdLuma: Math.sqrt(Math.max(sum2 / (width * height) - mean * mean, 0)),
  };
}

const failures = [];
const check = (ok, what) => {
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures.push(what);
};

const profile = mkdtempSync(join(tmpdir(), 'scarp-chromium-'));
const context = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1300, height: 1000 },
  args: [
    '--no-sandbox',
    '--disable-gpu',
    '--disable-quic',
    '--no-first-run',
    '--disable-background-networking',
    '--disable-component-update',
    '--disable-sync',
    // WebGL without a GPU: SwiftShader, Chromium's software renderer.
    '--use-gl=angle',
    '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader',
  ],
});
const result = {};
try {
  const page = context.pages()[0] || (await context.newPage());
  const errors = [];
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(`console.error: ${m.text()}`);
  });
  page.on('pageerror', (e) => errors.push(`uncaught: ${e.message}`));
  page.on('requestfailed', (r) => errors.push(`request failed: ${r.url()} ${r.failure()?.errorText}`));
  const url = 'file://' + resolve(reportPath);
  const started = Date.now();
  await page.goto(url, { waitUntil: 'load', timeout: 60_000 });
  await page.waitForFunction(() => typeof window.scarpViewerStats === 'function', null, { timeout: 60_000 });
  result.loadSeconds = (Date.now() - started) / 1000;
  const canvases = await page.locator('canvas').count();
  result.canvases = canvases;
  check(canvases > 0, `report has ${canvases} 3D view(s)`);

  const inPage = await page.evaluate(() => window.scarpViewerStats());
  result.inPage = inPage;
  for (const [id, s] of Object.entries(inPage)) {
    check(
      s.nonBackgroundFraction > 0.05 && s.stdLuma > 5 && s.distinctColours > 20,
      `target ${id} view (WebGL read-back): ${(100 * s.nonBackgroundFraction).toFixed(1)}% non-background, ` +
        `${s.distinctColours} colours, luma ${s.meanLuma.toFixed(1)} ± ${s.stdLuma.toFixed(1)}`
    );
  }

  const first = page.locator('canvas').first();
  await first.scrollIntoViewIfNeeded();
  const shotPath = join(outDir, 'report_view.png');
  const shot = await first.screenshot({ path: shotPath });
  const s = pixelStats(decodePng(shot));
  result.screenshot = { path: shotPath, ...s };
  check(
    s.nonBackgroundFraction > 0.05 && s.stdLuma > 5,
    `screenshot of the first view (${s.width}×${s.height}): ${(100 * s.nonBackgroundFraction).toFixed(1)}% non-background, ` +
      `${s.distinctColours} colours, luma ${s.meanLuma.toFixed(1)} ± ${s.stdLuma.toFixed(1)}`
  );
  await page.screenshot({ path: join(outDir, 'report_page.png'), fullPage: false });

  // The toggles: ground truth on, colours by error; the picture must change.
  const id = Object.keys(inPage)[0];
  const gtBox = page.locator(`input[data-target="${id}"][data-layer="gt"]`);
  if ((await gtBox.count()) > 0) {
    await gtBox.check();
    await page.locator(`input[data-target="${id}"][data-colour="error"]`).check();
    const toggled = pixelStats(decodePng(await first.screenshot({ path: join(outDir, 'report_view_error.png') })));
    result.toggled = toggled;
    const changed = Math.abs(toggled.meanLuma - s.meanLuma) + Math.abs(toggled.distinctColours - s.distinctColours);
    check(changed > 1, `ground-truth and error toggles change the view (luma ${s.meanLuma.toFixed(1)} → ${toggled.meanLuma.toFixed(1)}, colours ${s.distinctColours} → ${toggled.distinctColours})`);
    const legend = await page.locator(`#legend-${id}`).innerText();
    check(legend.includes('mm'), `error legend shown: "${legend.trim()}"`);
  } else {
    console.log(`(target ${id} has no ground truth: toggles not exercised)`);
  }
  // Orbit and zoom: a drag and a wheel turn change the picture.
  const box = await first.boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 30, { steps: 5 });
  await page.mouse.up();
  await page.mouse.wheel(0, 400);
  const orbited = pixelStats(decodePng(await first.screenshot()));
  result.orbited = orbited;
  check(orbited.nonBackgroundFraction > 0.01, `after orbit and zoom: ${(100 * orbited.nonBackgroundFraction).toFixed(1)}% non-background`);

  const polar = await page.locator('svg.polar').count();
  result.polarPlots = polar;
  const alphaRows = await page.locator('#alpha-table tr').count();
  check(alphaRows > 1, `α table has ${alphaRows - 1} row(s); ${polar} polar plot(s)`);

  result.errors = errors;
  check(errors.length === 0, `no console errors${errors.length ? ': ' + errors.join(' | ') : ''}`);
} finally {
  await context.close();
  rmSync(profile, { recursive: true, force: true });
}
writeFileSync(join(outDir, 'report_browser_test.json'), JSON.stringify(result, null, 2));
console.log(`report browser test: ${failures.length === 0 ? 'all checks passed' : failures.length + ' check(s) failed'}`);
process.exit(failures.length === 0 ? 0 : 1);
