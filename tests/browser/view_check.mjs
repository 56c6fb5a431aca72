// Opens the live view in Debian's chromium, headless (tests/pipeline_view.rs starts the
// demo): waits until the page says the run ended, writes a screenshot and prints the page's
// state (window.viewState) as JSON on stdout.
// Usage: node view_check.mjs URL SCREENSHOT.png  (CHROMIUM: the browser's path)
import { chromium } from 'playwright-core';

const [url, shot] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  args: ['--no-sandbox', '--disable-gpu'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 1100 } });
  const errors = [];
  page.on('pageerror', e => errors.push(String(e)));
  await page.goto(url);
  // Bounded waits (a hang is a failure, not a measurement).
  await page.waitForFunction(() => window.viewState && window.viewState.connected, null,
    { timeout: 60000 });
  await page.waitForFunction(() => window.viewState.state === 'run ended', null,
    { timeout: 180000, polling: 100 });
  // One more frame drawn after the last data.
  await page.evaluate(() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r))));
  await page.screenshot({ path: shot, fullPage: true });
  const state = await page.evaluate(() => JSON.parse(JSON.stringify(window.viewState)));
  state.errors = errors;
  console.log(JSON.stringify(state));
} finally {
  await browser.close();
}
