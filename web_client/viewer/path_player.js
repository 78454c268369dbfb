// A path playing on the viewer's camera (CatgsViewer.playPath): each step the camera takes the
// path's pose at that moment; a tour's waypoints are announced as it reaches them; the promise
// playPath returned resolves when it ends (true) or is stopped (false).

export class PathPlayer {
  constructor() {
    this.current = null; // { kind, at(t), duration, keys, secondsPerView, onWaypoint, shown, t0, resolve }
  }

  get kind() {
    return this.current ? this.current.kind : null;
  }

  // playback: pose_input.js playbackOf's { duration, at, keys }; options: kind, secondsPerView,
  // onWaypoint(index, waypoint). Stops the one playing.
  play(playback, { kind, secondsPerView, onWaypoint }) {
    this.stop();
    return new Promise((resolve) => {
      this.current = { ...playback, kind, secondsPerView, onWaypoint, shown: -1, t0: performance.now(), resolve };
    });
  }

  stop() {
    this._end(false);
  }

  _end(finished) {
    const pb = this.current;
    if (!pb) return;
    this.current = null;
    pb.resolve(finished);
  }

  // Moves `cam` to the path's pose at page time `now`; ends the path at its end.
  step(now, cam) {
    const pb = this.current;
    const t = (now - pb.t0) / 1000;
    const p = pb.at(Math.min(t, pb.duration));
    cam.setPose(p.position, p.orientation, p.fovDeg);
    if (pb.keys && pb.onWaypoint) {
      // The waypoint the tour is at (within a quarter second), once.
      const k = Math.round(Math.min(t, pb.duration) / pb.secondsPerView);
      if (k !== pb.shown && Math.abs(t - k * pb.secondsPerView) < 0.25 && pb.keys[k]) {
        pb.shown = k;
        pb.onWaypoint(k, pb.keys[k]);
      }
    }
    if (t >= pb.duration) this._end(true);
  }
}
