// Open /docs and /redoc in headless Chromium with every request to another host refused, and report whether
// the API title rendered and which outside requests were attempted (tests/browser/test_viewer.py).
// Usage: node docs_check.mjs BASE_URL
import { openBrowser, releaseBrowser } from './chromium.mjs';

const base = process.argv[2];
const origin = new URL(base).origin;
const browser = await openBrowser();
const out = {};
try {
  for (const [page, selector] of [['/docs', '.swagger-ui .info .title'], ['/redoc', 'h1']]) {
    const tab = await browser.newPage();
    const outside = [];
    await tab.setRequestInterception(true);
    tab.on('request', (r) => {
      const url = r.url();
      if (url.startsWith(origin) || url.startsWith('data:') || url.startsWith('blob:')) r.continue();
      else { outside.push(url); r.abort(); }
    });
    await tab.goto(base + page, { waitUntil: 'load', timeout: 120_000 });
    let title = null;
    try {
      await tab.waitForSelector(selector, { timeout: 120_000 });
      title = await tab.$eval(selector, (el) => el.textContent);
    } catch (err) {
      title = `not rendered: ${err.message}`;
    }
    out[page] = { title, outside };
    await tab.close();
  }
} finally {
  await releaseBrowser(browser);
}
console.log(JSON.stringify(out));
