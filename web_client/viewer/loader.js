// The embed's loader (issue 91): a classic script for the host page to copy inline (it must not
// come from the catgs server, which may be down when the page loads). It imports the viewer module
// from SRC; while that fails (server down, restarting, unreachable) each <catgs-viewer> on the
// page shows why in its own box with a countdown and gets an `error` event, the one the README's
// example listens to ({ name: 'UNREACHABLE', reason, retryInMs }); it tries again after 1, 2, 4,
// 8, then every 10 s (connection.js's backoff). Once the module loads, the elements become the
// viewer (its shadow root hides what the loader wrote) and stream. Copy from here to the end, with
// SRC set to the server's viewer/viewer.js.
(function catgsViewerLoader(given) {
  // Served as /viewer/loader.js (a script tag) it finds viewer.js beside itself.
  const src = given !== 'SRC' ? given : new URL('viewer.js', document.currentScript.src).href;
  const words = (secs) => `cannot reach the server, retrying ${secs > 0 ? `in ${secs} s` : 'now'}`;
  // The box until the element is defined: the host page's own CSS for catgs-viewer wins (:where).
  const style = document.createElement('style');
  style.textContent = ':where(catgs-viewer:not(:defined)){display:block;position:relative;height:360px;' +
    'background:#000;color:#ff9a8a;font:14px/1.4 system-ui,sans-serif;text-align:center}' +
    ':where(catgs-viewer:not(:defined)) > .catgs-loader{position:absolute;left:12px;right:12px;top:50%;' +
    'transform:translateY(-50%)}';
  document.head.appendChild(style);
  const boxes = () => Array.from(document.querySelectorAll('catgs-viewer'));
  const say = (text) => {
    for (const el of boxes()) {
      let line = el.querySelector(':scope > .catgs-loader');
      if (!line) {
        line = document.createElement('div');
        line.className = 'catgs-loader';
        line.setAttribute('role', 'status');
        el.appendChild(line);
      }
      line.textContent = text;
    }
  };
  // A failed module fetch stays failed in the page's module map: the server is asked with fetch
  // until it answers, and only then is the module imported (a fresh URL if that import failed).
  let attempt = 0, imports = 0, timer = 0;
  // A failure can come back before the page is parsed (a refused connection is quick): the boxes
  // after this script and the page's own listeners (its module scripts run before
  // DOMContentLoaded) are not there yet, so the words and the event wait for them.
  const parsed = (f) =>
    document.readyState === 'loading' ? document.addEventListener('DOMContentLoaded', f, { once: true }) : f();
  const retry = (reason) => parsed(() => {
    const wait = Math.min(1000 * 2 ** attempt++, 10000), at = performance.now() + wait;
    for (const el of boxes()) {
      el.dispatchEvent(new CustomEvent('error', { detail: { name: 'UNREACHABLE', reason, retryInMs: wait, permanent: false } }));
    }
    clearInterval(timer);
    const tick = () => say(words(Math.ceil((at - performance.now()) / 1000)));
    tick();
    timer = setInterval(tick, 500);
    setTimeout(load, wait);
  });
  const load = () => fetch(src, { cache: 'no-store', mode: 'cors' })
    .then((r) => {
      if (!r.ok) throw new Error(`${src}: HTTP ${r.status}`);
      return import(imports++ ? `${src}?load=${imports}` : src);
    })
    .then(() => {
      clearInterval(timer);
      for (const el of boxes()) el.querySelector(':scope > .catgs-loader')?.remove();
    }, (e) => retry(`cannot load the viewer from ${src}: ${e.message}`));
  load();
})('SRC');
