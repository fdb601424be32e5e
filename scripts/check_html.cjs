#!/usr/bin/env node
// Opens an HTML file in headless Chromium and reports what a reader of the page would meet:
// console errors, uncaught exceptions, resources that failed to load, images that do not
// decode, and how many elements match a selector. Chromium is driven through the DevTools
// protocol over a pipe (--remote-debugging-pipe: no port, no network), with a fresh profile.
//
// Usage: node scripts/check_html.cjs FILE.html [--count SELECTOR]
// Environment: MESA_CHROMIUM, the browser to run (default: chromium, Debian's package).
// Prints one JSON object: {"file", "errors": [...], "count", "images", "broken_images"}, then
// exits 0 when there is no error, 1 when there are errors, 2 on bad usage or when the browser
// cannot be started.
'use strict';

const { spawn } = require('child_process');
const fs = require('fs');
const os = require('os');
const path = require('path');
const { pathToFileURL } = require('url');

function usage(message) {
  console.error(`check_html: ${message}\nusage: node scripts/check_html.cjs FILE.html [--count SELECTOR]`);
  process.exit(2);
}

const args = process.argv.slice(2);
let file = null;
let selector = null;
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--count') {
    selector = args[++i];
    if (!selector) usage('--count needs a selector');
  } else if (file === null) {
    file = args[i];
  } else {
    usage(`unexpected argument ${args[i]}`);
  }
}
if (!file) usage('no file given');
if (!fs.existsSync(file)) usage(`${file}: no such file`);

const browser = process.env.MESA_CHROMIUM || 'chromium';
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'mesa-chromium-'));
const child = spawn(
  browser,
  [
    '--headless',
    '--no-sandbox',
    '--disable-gpu',
    '--disable-quic',
    '--no-first-run',
    '--disable-background-networking',
    '--disable-component-update',
    '--disable-sync',
    `--user-data-dir=${profile}`,
    '--remote-debugging-pipe',
    'about:blank',
  ],
  // The protocol pipe: the browser reads commands on fd 3 and writes replies on fd 4.
  { stdio: ['ignore', 'ignore', 'pipe', 'pipe', 'pipe'] },
);
let stderr = '';
child.stderr.on('data', (d) => { stderr += d; });

let finishing = false;
function finish(code, report) {
  if (finishing) return;
  finishing = true;
  if (report) console.log(JSON.stringify(report));
  // The profile is removed once the browser has exited (it writes there until then).
  const done = () => {
    try { fs.rmSync(profile, { recursive: true, force: true, maxRetries: 5 }); } catch (_) { /* best effort */ }
    process.exit(code);
  };
  if (child.pid === undefined || child.exitCode !== null || child.signalCode !== null) {
    done();
    return;
  }
  child.once('exit', done);
  try { child.kill('SIGKILL'); } catch (_) { done(); }
  setTimeout(done, 5000).unref();
}

child.on('error', (e) => {
  console.error(`check_html: cannot start ${browser}: ${e.message} (install Debian's chromium, or set MESA_CHROMIUM)`);
  finish(2);
});

const timer = setTimeout(() => {
  console.error(`check_html: ${browser} did not finish within 90 s; its log:\n${stderr.slice(-2000)}`);
  finish(2);
}, 90000);

const commands = child.stdio[3];
const replies = child.stdio[4];
let nextId = 1;
const pending = new Map();
const listeners = [];
let buffer = Buffer.alloc(0);
replies.on('data', (chunk) => {
  buffer = Buffer.concat([buffer, chunk]);
  let end;
  while ((end = buffer.indexOf(0)) >= 0) {
    const message = JSON.parse(buffer.subarray(0, end).toString('utf8'));
    buffer = buffer.subarray(end + 1);
    if (message.id !== undefined && pending.has(message.id)) {
      const { resolve, reject } = pending.get(message.id);
      pending.delete(message.id);
      if (message.error) reject(new Error(`${message.error.message} (${message.error.code})`));
      else resolve(message.result);
    } else if (message.method) {
      for (const listener of listeners) listener(message);
    }
  }
});

function send(method, params = {}, sessionId = undefined) {
  const id = nextId++;
  const message = { id, method, params };
  if (sessionId) message.sessionId = sessionId;
  commands.write(JSON.stringify(message) + '\0');
  return new Promise((resolve, reject) => pending.set(id, { resolve, reject }));
}

async function main() {
  const errors = [];
  let loaded;
  const loadedPromise = new Promise((resolve) => { loaded = resolve; });
  listeners.push((m) => {
    const p = m.params || {};
    if (m.method === 'Runtime.exceptionThrown') {
      const d = p.exceptionDetails || {};
      errors.push(`exception: ${(d.exception && d.exception.description) || d.text}`);
    } else if (m.method === 'Runtime.consoleAPICalled' && (p.type === 'error' || p.type === 'assert')) {
      errors.push(`console.${p.type}: ${(p.args || []).map((a) => a.value !== undefined ? a.value : a.description).join(' ')}`);
    } else if (m.method === 'Log.entryAdded' && p.entry && p.entry.level === 'error') {
      errors.push(`${p.entry.source}: ${p.entry.text}${p.entry.url ? ' ' + p.entry.url : ''}`);
    } else if (m.method === 'Network.loadingFailed') {
      errors.push(`failed to load (${p.errorText}): request ${p.requestId}`);
    } else if (m.method === 'Page.loadEventFired') {
      loaded();
    }
  });
  const { targetId } = await send('Target.createTarget', { url: 'about:blank' });
  const { sessionId } = await send('Target.attachToTarget', { targetId, flatten: true });
  for (const domain of ['Runtime', 'Log', 'Page', 'Network']) {
    await send(`${domain}.enable`, {}, sessionId);
  }
  const url = pathToFileURL(path.resolve(file)).href;
  const navigation = await send('Page.navigate', { url }, sessionId);
  if (navigation.errorText) errors.push(`navigation: ${navigation.errorText}`);
  await loadedPromise;
  // Lazy images below the fold load only when scrolled to: load and decode every one.
  const images = await send('Runtime.evaluate', {
    expression: `Promise.all([...document.images].map((img) => { img.loading = 'eager';
       return img.decode().then(() => null, () => img.getAttribute('src')); }))
       .then((r) => ({ total: r.length, broken: r.filter((x) => x !== null) }))`,
    awaitPromise: true,
    returnByValue: true,
  }, sessionId);
  // Let the console and network events of those loads arrive.
  await new Promise((resolve) => setTimeout(resolve, 300));
  let count = null;
  if (selector) {
    const counted = await send('Runtime.evaluate', {
      expression: `document.querySelectorAll(${JSON.stringify(selector)}).length`,
      returnByValue: true,
    }, sessionId);
    count = counted.result.value;
  }
  const result = images.result.value || { total: 0, broken: [] };
  for (const src of result.broken) errors.push(`image does not load: ${src}`);
  await send('Browser.close').catch(() => {});
  clearTimeout(timer);
  finish(errors.length ? 1 : 0, {
    file,
    errors,
    count,
    images: result.total,
    broken_images: result.broken.length,
  });
}

main().catch((e) => {
  clearTimeout(timer);
  console.error(`check_html: ${e.message}; ${browser} said:\n${stderr.slice(-2000)}`);
  finish(2);
});
