// The access token (server/README.md "Limits"): taken once from the page's URL (?token=...),
// then removed from the address bar and the history entry, so it does not linger in bookmarks,
// shared links, screenshots or the browser history; kept in sessionStorage (this tab only, gone
// when the tab closes) for reconnects and reloads.

export const TOKEN_KEY = 'catgs.token';

// `loc`: window.location (href); `storage`: sessionStorage; `hist`: window.history.
// Returns the token ('' when there is none).
export function takeToken(loc, storage, hist) {
  const url = new URL(loc.href);
  const fromUrl = url.searchParams.get('token');
  if (fromUrl === null) return storage.getItem(TOKEN_KEY) || '';
  url.searchParams.delete('token');
  hist.replaceState(hist.state, '', url.toString());
  if (fromUrl) storage.setItem(TOKEN_KEY, fromUrl);
  return fromUrl || storage.getItem(TOKEN_KEY) || '';
}
