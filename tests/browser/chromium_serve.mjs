// One headless Chromium for every check script of a test module (tests/browser/test_viewer.py): prints its
// DevTools endpoint (for PDEANIM_BROWSER_WS) on one line, then runs until its stdin closes.
import { launchChromium } from './chromium.mjs';

const browser = await launchChromium();
console.log(browser.wsEndpoint());
process.stdin.resume();
process.stdin.on('end', async () => {
  await browser.close();
  process.exit(0);
});
