// The page's one message that says where the connection stands (the viewer library's words,
// status_text.js), with its action: "retry now", the token field, or the scene picker.
// README.md "States".
import { ERROR_WORDS, statusText } from './viewer/viewer.js';

export { ERROR_WORDS };

// The message for `viewer` now: { text, level, actions } to show, null to clear it, undefined to
// leave it as it is. `ui`: { retry (the retry button, one array so the overlay keeps it),
// tokenForm() (the token field's form, made once), sceneChoice() (the picker's form), sceneParam }.
// Refreshed by the page's loop, for the countdowns.
export function stateMessage(viewer, ui) {
  const words = statusText(viewer, ui.sceneParam);
  if (!words) return words;
  switch (viewer.status) {
    case 'unreachable':
    case 'server-full':
    case 'restarting':
    case 'stopping':
    case 'disconnected':
      return { ...words, actions: ui.retry };
    case 'no-scene':
      // The scene picker, filled from GET /scenes, in the message: a plain choice, no retries.
      return { ...words, text: `${words.text} Choose one:`, actions: ui.sceneChoice() };
    case 'needs-token':
      return {
        text: viewer.token ? 'wrong token: enter the access token' : words.text,
        level: words.level,
        actions: ui.tokenForm(),
      };
    default:
      return words;
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
