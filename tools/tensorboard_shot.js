// Screenshots of TensorBoard in headless Chromium (docs/img/tensorboard-*.png), as taken for the docs:
//   apt-get install -y chromium; npm install --prefix /tmp/pw playwright-core; export NODE_PATH=/tmp/pw/node_modules
//   .venv/bin/tensorboard --logdir tensorboard_logs/quickstart/seed-0 --port 6124 --host 127.0.0.1 &
//   node tools/tensorboard_shot.js 'http://127.0.0.1:6124/?darkMode=false#timeseries' docs/img/tensorboard-weathers.png '' 'episode/(in_22_25_pct|power_kw)$' 1030 510
// node tools/tensorboard_shot.js URL OUT.png RUN_REGEX TAG_REGEX [WIDTH HEIGHT]: Debian's Chromium, a fresh profile.
const fs = require('fs');
const os = require('os');
const path = require('path');
const { chromium } = require('playwright-core');
(async () => {
  const [url, out, runs, tags, w = '1400', h = '820'] = process.argv.slice(2);
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'tensorboard-shot-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium', headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update',
           '--disable-sync', '--no-first-run'],
    viewport: { width: +w, height: +h },
  });
  const page = await context.newPage();
  await page.goto(url, { waitUntil: 'networkidle' });
  await page.waitForTimeout(3000);
  const table = page.getByText('Enable step selection and data table');
  if (await table.count()) await table.first().click();
  const close = page.locator('button[aria-label="Close side pane"], .settings-pane button:has(mat-icon[svgicon="close_24px"])');
  if (await close.count()) await close.first().click();
  if (runs) await page.locator('input[placeholder="Filter runs (regex)"]').pressSequentially(runs, { delay: 50 });
  if (tags) await page.locator('input[placeholder="Filter tags (regex)"]').pressSequentially(tags, { delay: 50 });
  await page.keyboard.press('Escape');
  await page.mouse.click(700, 780);
  await page.waitForTimeout(6000);
  await page.screenshot({ path: out });
  console.log(await page.title());
  await context.close();
  fs.rmSync(profile, { recursive: true, force: true });
})();
