// The viewer library's old entry path (/viewer.js), kept so that pages which import it from
// before the library had its own folder keep working. New pages import /viewer/viewer.js.
export * from './viewer/viewer.js';
