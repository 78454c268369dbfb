// Whether the page's thread was busy (a long task) within the last moments (issue 64): a heartbeat
// every 20 ms that came more than 50 ms late, or none for 70 ms. Messages that waited behind the
// busy thread are handled right after it, whichever task runs first, so a frame's arrival read
// then says when the thread came back, not when the frame came: the viewer sends no receipt for
// it (a busy page would look like a slow link to the server's rate controller).

export class PageBusy {
  constructor(now = () => performance.now()) {
    this.now = now;
    this.beatMs = now();
    this.busyUntilMs = 0;
    this.timer = null;
  }

  start() {
    if (this.timer !== null) return;
    this.beatMs = this.now();
    this.timer = setInterval(() => this.beat(), 20);
  }

  stop() {
    clearInterval(this.timer);
    this.timer = null;
  }

  // One heartbeat: late ones mark the page busy for the next 100 ms.
  beat() {
    const now = this.now();
    if (now - this.beatMs > 70) this.busyUntilMs = now + 100;
    this.beatMs = now;
  }

  recently() {
    const now = this.now();
    return now - this.beatMs > 70 || now < this.busyUntilMs;
  }
}
