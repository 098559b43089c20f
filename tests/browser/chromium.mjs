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
