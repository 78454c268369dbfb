// The viewer's status in words (CatgsViewer.status; README.md "States"): what the full page and
// the embedded element (<catgs-viewer>) say when they cannot stream. Part of the viewer library:
// it imports nothing from the page.

// Why the server ended a session (ErrorCode), for "disconnected" (the others have their own words).
export const ERROR_WORDS = {
  1: 'the server could not read a message from this page',
  2: 'the page and the server do not speak the same protocol version',
  3: 'the server rejected a request from this page',
  6: 'the server failed to render or encode',
  8: 'the connection was too slow for the stream',
  9: 'this page sent more requests than the server allows',
  10: 'the connection was idle too long',
};

// { text, level } for `viewer` now (level: 'info', 'warn' or 'error'); null while it streams;
// undefined for a status it has no words for. `scene`: the scene the page asked for (the words
// of 'no-scene'). The countdowns read the clock: call it again to refresh them.
export function statusText(viewer, scene = '') {
  const secs = () => Math.max(0, Math.ceil((viewer.reconnectAt - performance.now()) / 1000));
  const when = () => (secs() > 0 ? `in ${secs()} s` : 'now');
  const closeError = () => viewer.closeInfo && viewer.closeInfo.error;
  switch (viewer.status) {
    case 'connecting':
    case 'handshake':
      return { text: 'connecting to the server…', level: 'info' };
    case 'loading-scene': {
      // The server loads a scene on its first use; LoadProgress comes until Welcome.
      const p = viewer.loadProgress || { scene_name: '', percent: 0 };
      return { text: `loading scene ${p.scene_name}: ${p.percent}%`, level: 'info' };
    }
    case 'first-view':
      return { text: 'rendering the first view…', level: 'info' };
    case 'streaming': {
      // A draining server (a rollout, a scale-down): when this stream ends; the reconnect then
      // finds another replica, or this one back.
      const left = viewer.drainEndsAt ? Math.ceil((viewer.drainEndsAt - performance.now()) / 1000) : 0;
      return left > 0 ? { text: `server stopping: this stream ends in ${left} s, then reconnects`, level: 'warn' } : null;
    }
    case 'unreachable':
      return { text: `cannot reach the server, retrying ${when()}`, level: 'error' };
    case 'server-full': {
      // A server refuses with SERVER_FULL while its first scene loads too ("server starting: the
      // scene is loading", server.cpp): not full, and asked back in a few hundred ms.
      const e = closeError();
      if (e && /^server starting/.test(e.reason || '')) return { text: `the server is starting (loading its scene), retrying ${when()}`, level: 'info' };
      return { text: `server full, retrying ${when()}`, level: 'warn' };
    }
    case 'restarting':
    case 'stopping':
      return { text: `server ${viewer.status}, reconnecting ${when()}`, level: 'warn' };
    case 'no-scene': {
      // The server's reason lists what it has ("no scene 'x' on this server (it has: a, b)").
      const e = closeError();
      const has = e && /\(it has: (.+)\)$/.exec(e.reason || '');
      return { text: `There is no scene named '${scene}' on this server${has ? `; it has ${has[1]}` : ''}.`, level: 'warn' };
    }
    case 'needs-token':
      return { text: viewer.token ? 'wrong token: this view needs another access token' : 'this server needs an access token',
        level: 'error' };
    case 'refused': {
      const e = closeError();
      return { text: `the server refused this page: ${(e && e.reason) || 'protocol error'} (reload the page)`, level: 'error' };
    }
    case 'disconnected': {
      const e = closeError();
      const why = e ? `${ERROR_WORDS[e.code] || 'the server ended the session'}${e.reason ? ` (${e.reason})` : ''}; ` : 'disconnected, ';
      return { text: `${why}reconnecting ${when()}`, level: e ? 'error' : 'warn' };
    }
    case 'unsupported':
    case 'origin-refused':
    case 'error':
      return { text: viewer.startError, level: 'error' };
    default:
      return undefined;
  }
}
