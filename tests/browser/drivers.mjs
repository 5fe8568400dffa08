// One small interface over the three browser engines the tests drive, all Debian packages (no
// browser is downloaded):
//   Chromium  /usr/bin/chromium, by playwright-core;
//   Firefox   /usr/bin/firefox-esr, headless, by puppeteer-core over WebDriver BiDi;
//   WebKit    WebKitGTK's MiniBrowser under Xvfb, by its WebDriver (WebKitWebDriver), spoken to
//             directly over HTTP (the W3C protocol: a few requests, no client library).
//
// launch(engine, { gpu }) resolves to a browser whose open(url) gives a page with:
//   evaluate(fn, arg)   runs fn(arg) in the page (a promise is awaited), returns its JSON value
//   click(selector), press(key), setFiles(selector, paths), screenshot(selector) (PNG bytes)
//   close()
// open(url, { reducedMotion: true }) opens it with prefers-reduced-motion: reduce.
// `gpu: false` launches the engine with WebGPU and WebGL disabled (flags or preferences).

import { chromium } from 'playwright-core';
import { spawn } from 'node:child_process';
import { mkdtemp, rm } from 'node:fs/promises';
import { existsSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { setTimeout as sleep } from 'node:timers/promises';

export const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
export const FIREFOX = process.env.FIREFOX ?? '/usr/bin/firefox-esr';
export const MINIBROWSER = process.env.MINIBROWSER ?? '/usr/lib/x86_64-linux-gnu/webkit2gtk-4.1/MiniBrowser';
const WEBKIT_DRIVER = process.env.WEBKIT_DRIVER ?? '/usr/bin/WebKitWebDriver';

// Which engines are installed here.
export const INSTALLED = {
  chromium: existsSync(CHROMIUM),
  firefox: existsSync(FIREFOX),
  webkit: existsSync(MINIBROWSER) && existsSync(WEBKIT_DRIVER),
};

const CHROMIUM_FLAGS = [
  '--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--no-first-run', '--disable-quic', '--window-size=1280,900',
];
// WebGPU on SwiftShader (the three GPU flags are all needed), and WebGL2 through ANGLE on it.
const CHROMIUM_GPU = ['--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
  '--use-angle=swiftshader', '--enable-unsafe-swiftshader'];

export async function launch(engine, { gpu = true } = {}) {
  if (engine === 'chromium') return launchChromium(gpu);
  if (engine === 'firefox') return launchFirefox(gpu);
  if (engine === 'webkit') return launchWebKit(gpu);
  throw new Error(`unknown engine ${engine}`);
}

// --- Chromium (playwright-core) ----------------------------------------------------------------
async function launchChromium(gpu) {
  const profile = await mkdtemp(path.join(tmpdir(), 'monolayer-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM, headless: true, viewport: { width: 1280, height: 900 },
    args: [...CHROMIUM_FLAGS, ...(gpu ? CHROMIUM_GPU : ['--disable-3d-apis'])],
  });
  return {
    engine: 'chromium',
    cdp: (page) => context.newCDPSession(page.raw),
    async open(url, { reducedMotion = false } = {}) {
      const page = await context.newPage();
      if (reducedMotion) await page.emulateMedia({ reducedMotion: 'reduce' });
      const errors = watch(page);
      await page.goto(url);
      return {
        raw: page, errors,
        evaluate: (fn, arg) => page.evaluate(fn, arg),
        click: (sel) => page.click(sel),
        press: (key) => page.keyboard.press(key),
        setFiles: (sel, paths) => page.setInputFiles(sel, paths),
        screenshot: (sel) => page.locator(sel).screenshot(),
        close: () => page.close(),
      };
    },
    async close() {
      await context.close();
      await rm(profile, { recursive: true, force: true });
    },
  };
}

function watch(page) {
  const errors = [];
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => errors.push(`pageerror: ${e.message}`));
  return errors;
}

// --- Firefox (puppeteer-core over WebDriver BiDi) ---------------------------------------------
async function launchFirefox(gpu, reducedMotion = false) {
  const puppeteer = (await import('puppeteer-core')).default;
  // Headless Firefox has WebGPU only with these preferences (and no WebGL2 either way).
  const prefs = gpu
    ? { 'dom.webgpu.enabled': true, 'gfx.webgpu.ignore-blocklist': true, 'webgl.force-enabled': true }
    : { 'dom.webgpu.enabled': false, 'webgl.disabled': true };
  // Emulating media features needs CDP, which Firefox lacks: a preference of its own browser.
  if (reducedMotion) prefs['ui.prefersReducedMotion'] = 1;
  const browser = await puppeteer.launch({
    browser: 'firefox', executablePath: FIREFOX, headless: true, extraPrefsFirefox: prefs,
    defaultViewport: { width: 1280, height: 900 },
  });
  return {
    engine: 'firefox',
    async open(url, { reducedMotion: reduce = false } = {}) {
      if (reduce && !reducedMotion) {
        const own = await launchFirefox(gpu, true);
        const page = await own.open(url);
        const close = page.close;
        page.close = async () => {
          await close();
          await own.close();
        };
        return page;
      }
      const page = await browser.newPage();
      const errors = [];
      page.on('console', (m) => {
        if (m.type() === 'error') errors.push(`console: ${m.text()}`);
      });
      page.on('pageerror', (e) => errors.push(`pageerror: ${e.message}`));
      await page.goto(url);
      return {
        raw: page, errors,
        evaluate: (fn, arg) => page.evaluate(fn, arg),
        click: (sel) => page.click(sel),
        press: (key) => page.keyboard.press(key),
        setFiles: async (sel, paths) => (await page.$(sel)).uploadFile(...paths),
        screenshot: async (sel) => Buffer.from(await (await page.$(sel)).screenshot()),
        close: () => page.close(),
      };
    },
    close: () => browser.close(),
  };
}

// --- WebKit (MiniBrowser by WebKitWebDriver, W3C WebDriver over HTTP) --------------------------
let xvfb = null;
// A private X display for MiniBrowser (it has no headless mode), shared by every WebKit launch.
async function display() {
  if (process.env.DISPLAY) return process.env.DISPLAY;
  if (!xvfb) {
    const n = 90 + Math.floor(Math.random() * 400);
    const proc = spawn('Xvfb', [`:${n}`, '-screen', '0', '1400x1000x24', '-nolisten', 'tcp'], { stdio: 'ignore' });
    xvfb = { proc, name: `:${n}` };
    // Not a reason for Node to stay: once the tests are done the process exits, and Xvfb with it.
    proc.unref();
    process.on('exit', () => proc.kill());
    await sleep(500);
  }
  return xvfb.name;
}

// WebDriver's codes of the named keys the checks press.
const KEYS = { Escape: '\uE00C', Enter: '\uE007', Space: ' ' };

async function launchWebKit(gpu) {
  const port = 4400 + Math.floor(Math.random() * 500);
  const env = { ...process.env, DISPLAY: await display() };
  const driver = spawn(WEBKIT_DRIVER, [`--port=${port}`], { env, stdio: 'ignore' });
  const url = `http://127.0.0.1:${port}`;
  const call = async (method, route, body) => {
    for (let attempt = 0; ; attempt++) {
      try {
        const res = await fetch(url + route, { method, headers: { 'content-type': 'application/json' }, body: body && JSON.stringify(body) });
        const json = await res.json();
        if (json.value?.error) throw new Error(`WebDriver ${route}: ${json.value.error}: ${json.value.message}`);
        return json.value;
      } catch (e) {
        // The driver takes a moment to listen after it starts.
        if (attempt > 50 || !/ECONNREFUSED|fetch failed/.test(String(e.cause ?? e))) throw e;
        await sleep(100);
      }
    }
  };
  // MiniBrowser takes WebKitSettings on its command line: without the GPU, no WebGL (WebKitGTK
  // has no WebGPU here at all).
  const args = ['--automation', ...(gpu ? [] : ['--enable-webgl=false'])];
  let session;
  const open = async (address) => {
    session = await call('POST', '/session', {
      capabilities: { alwaysMatch: { browserName: 'MiniBrowser', 'webkitgtk:browserOptions': { binary: MINIBROWSER, args } } },
    });
    const s = `/session/${session.sessionId}`;
    await call('POST', `${s}/window/rect`, { width: 1280, height: 900 }).catch(() => {});
    await call('POST', `${s}/url`, { url: address });
    const element = async (sel) => Object.values(await call('POST', `${s}/element`, { using: 'css selector', value: sel }))[0];
    return {
      errors: [],
      // A promise returned by the script is awaited (W3C WebDriver, Execute Script).
      evaluate: (fn, arg) => call('POST', `${s}/execute/sync`, { script: `return (${fn})(arguments[0]);`, args: [arg ?? null] }),
      click: async (sel) => call('POST', `${s}/element/${await element(sel)}/click`, {}),
      press: (key) => {
        const value = KEYS[key] ?? key;
        return call('POST', `${s}/actions`, {
          actions: [{ type: 'key', id: 'keyboard', actions: [{ type: 'keyDown', value }, { type: 'keyUp', value }] }],
        });
      },
      setFiles: async (sel, paths) => call('POST', `${s}/element/${await element(sel)}/value`, { text: paths.join('\n') }),
      screenshot: async (sel) => Buffer.from(await call('GET', `${s}/element/${await element(sel)}/screenshot`), 'base64'),
      close: () => call('DELETE', s).catch(() => {}),
    };
  };
  return {
    engine: 'webkit',
    // WebKitWebDriver drives one page per session: each open() is a new MiniBrowser.
    async open(address, { reducedMotion = false } = {}) {
      if (reducedMotion) throw new Error('WebKitWebDriver cannot ask for prefers-reduced-motion');
      return open(address);
    },
    async close() {
      driver.kill();
    },
  };
}
