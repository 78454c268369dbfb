// The page's one message that says where the connection stands (CatgsViewer.status in words),
// with its action: "retry now", the token field, or the scene picker. README.md "States".

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

// The message for `viewer` now: { text, level, actions } to show, null to clear it, undefined to
// leave it as it is. `ui`: { retry (the retry button, one array so the overlay keeps it),
// tokenForm() (the token field's form, made once), sceneChoice() (the picker's form), sceneParam }.
// Refreshed by the page's loop, for the countdowns.
export function stateMessage(viewer, ui) {
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
    case 'streaming':
      return null;
    case 'unreachable':
      return { text: `cannot reach the server, retrying ${when()}`, level: 'error', actions: ui.retry };
    case 'server-full':
      return { text: `server full, retrying ${when()}`, level: 'warn', actions: ui.retry };
    case 'restarting':
    case 'stopping':
      return { text: `server ${viewer.status}, reconnecting ${when()}`, level: 'warn', actions: ui.retry };
    case 'no-scene':
      // The scene picker, filled from GET /scenes, in the message: a plain choice, no retries.
      return { text: `There is no scene named '${ui.sceneParam}' on this server. Choose one:`, level: 'warn', actions: ui.sceneChoice() };
    case 'needs-token':
      return {
        text: viewer.token ? 'wrong token: enter the access token' : 'this server needs an access token',
        level: 'error',
        actions: ui.tokenForm(),
      };
    case 'refused': {
      const e = closeError();
      return { text: `the server refused this page: ${(e && e.reason) || 'protocol error'} (reload the page)`, level: 'error' };
    }
    case 'disconnected': {
      const e = closeError();
      const why = e ? `${ERROR_WORDS[e.code] || 'the server ended the session'}${e.reason ? ` (${e.reason})` : ''}; ` : 'disconnected, ';
      return { text: `${why}reconnecting ${when()}`, level: e ? 'error' : 'warn', actions: ui.retry };
    }
    case 'unsupported':
    case 'error':
      return { text: viewer.startError, level: 'error' };
    default:
      return undefined;
  }
}

// The token field: `onToken(token)` when one is entered (the page keeps it and reconnects).
export function makeTokenForm(onToken) {
  const form = document.createElement('form');
  const input = document.createElement('input');
  input.type = 'password';
  input.name = 'token';
  input.id = 'token-input';
  input.placeholder = 'access token';
  input.autocomplete = 'current-password';
  input.setAttribute('aria-label', 'access token');
  const button = document.createElement('button');
  button.type = 'submit';
  button.textContent = 'connect';
  form.append(input, button);
  form.addEventListener('submit', (e) => {
    e.preventDefault();
    const token = input.value.trim();
    input.value = '';
    onToken(token);
  });
  return form;
}
