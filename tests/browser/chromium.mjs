// Launch Debian's chromium (or $PDEANIM_CHROMIUM) headless with software WebGL (SwiftShader), for tests and
// benchmarks.
import { existsSync } from 'node:fs';
import puppeteer from 'puppeteer-core';

export const CANDIDATES = ['/usr/bin/chromium', '/usr/bin/chromium-browser', '/usr/bin/google-chrome'];

export function chromiumPath() {
  const path = process.env.PDEANIM_CHROMIUM || process.env.CHROMIUM || CANDIDATES.find((p) => existsSync(p));
  if (!path) throw new Error('no chromium found: apt-get install chromium, or set PDEANIM_CHROMIUM');
  return path;
}

export function launchChromium(extraArgs = []) {
  return puppeteer.launch({
    executablePath: chromiumPath(),
    headless: true,
    args: ['--no-sandbox', '--disable-dev-shm-usage', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', ...extraArgs],
    timeout: 120_000,
    protocolTimeout: 300_000,
  });
}

// The browser of a check script: the one a test module shares (PDEANIM_BROWSER_WS, the endpoint that
// chromium_serve.mjs prints) when there is one, else a browser of its own; release it with releaseBrowser.
export function openBrowser() {
  const ws = process.env.PDEANIM_BROWSER_WS;
  return ws ? puppeteer.connect({ browserWSEndpoint: ws, protocolTimeout: 300_000 }) : launchChromium();
}

export function releaseBrowser(browser) {
  return process.env.PDEANIM_BROWSER_WS ? browser.disconnect() : browser.close();
}
