// window.catgs: a small, stable surface for the browser tests (and the console) to drive the page
// deterministically, on the viewer's API and the page's own actions (README.md "Test hook").

// viewer: the CatgsViewer; page: the page's actions and state (app.js): overlay, shareUrl,
// resetView, toggleRecording, recording(), addWaypoint, play, exportCameras, exportTrace,
// importText, setRenderScale, setMaxBitrate, notes, walk, toggleWalk, videoExport.
export function installTestHook(viewer, page) {
  const errors = []; // every error event's detail, from the start
  viewer.addEventListener('error', (e) => errors.push({ ...e.detail }));
  window.catgs = {
    get errors() {
      return errors.map((e) => ({ ...e }));
    },
    get framesDecoded() {
      return viewer.framesDecoded;
    },
    get lastFrame() {
      return viewer.lastFrame ? { ...viewer.lastFrame } : null;
    },
    get lastPoseSent() {
      return viewer.lastPoseSent ? { ...viewer.lastPoseSent } : null;
    },
    // The codecs the page offered in Hello (decoder.js decodableCodecs, or ?codec=h264).
    get codecs() {
      return [...viewer.codecs];
    },
    get welcome() {
      return viewer.welcome;
    },
    get status() {
      return viewer.status;
    },
    get connected() {
      return viewer.connected;
    },
    get viewport() {
      return viewer.viewport ? { ...viewer.viewport } : null;
    },
    get decoderErrors() {
      return viewer.decoderErrors;
    },
    // Sets the camera and sends the pose at once; returns its sequence (null if not connected).
    setPose: (position, orientation, fovDeg) => viewer.setPose({ position, orientation, fovDeg }),
    pose: () => viewer.pose(),
    // Asks for an IDR and re-sends the current pose; returns that pose's sequence.
    requestKeyFrame: () => viewer.requestKeyFrame(),
    overlayText: () => page.overlay.text(),
    // The canvas as a PNG data URL: exactly the decoded pixels, without the overlay on top.
    snapshot: () => viewer.snapshot(),
    shareUrl: page.shareUrl,
    resetView: page.resetView,
    // Camera paths: the same actions as the Paths panel, files returned as text.
    toggleRecording: page.toggleRecording,
    get recording() {
      const r = page.recording();
      return r ? r.map((s) => ({ ...s })) : null;
    },
    addWaypoint: page.addWaypoint,
    play: page.play,
    get playing() {
      return viewer.playing;
    },
    exportCameras: page.exportCameras,
    exportTrace: page.exportTrace,
    importText: page.importText,
    setRenderScale: page.setRenderScale,
    setMaxBitrate: page.setMaxBitrate,
    // Hotspots, measurement, walk mode (issue 38).
    probe: (x, y) => viewer.probe(x, y), // (cssX, cssY) -> Promise<DepthResult as an object>
    // The shown frame's depth under CSS pixel (x, y) from its depth grid (no round trip), or null.
    frameDepthAt: (x, y) => viewer.frameDepthAt(x, y),
    probePose: (pose, width, height, x, y) => viewer.probePose(pose, width, height, x, y),
    get notes() {
      return page.notes.snapshot();
    },
    setNotesMode: (mode) => page.notes.setMode(mode),
    pick: (x, y) => page.notes.pick(x, y),
    addHotspot: (title, text, keepView) => page.notes.addHotspot(title, text, keepView),
    openHotspot: (id) => page.notes.open(id),
    hotspotTour: () => page.notes.tour(),
    setScale: (metres) => page.notes.setScale(metres),
    saveNotes: () => page.notes.save(),
    toggleWalk: page.toggleWalk,
    // VR (issue 94): the session's state (xr.js snapshot(), null when not in VR), the button's
    // action, leaving, and the next display frame's pixels as PNG (both eyes, as the headset
    // gets them) with the state at that frame.
    get vr() {
      return viewer.vr ? viewer.vr.snapshot() : null;
    },
    toggleVr: page.toggleVr,
    exitVr: () => viewer.exitVr(),
    vrCapture: async () => {
      if (!viewer.vr) return null;
      const shot = await viewer.vr.capture();
      const c = document.createElement('canvas');
      c.width = shot.width;
      c.height = shot.height;
      c.getContext('2d').putImageData(new ImageData(shot.rgba, shot.width, shot.height), 0, 0);
      const { rgba, ...rest } = shot;
      return { ...rest, png: c.toDataURL('image/png') };
    },
    get walk() {
      return page.walk.snapshot();
    },
    walkTrace: (on) => page.walk.takeTrace(on), // starts a trace of walk steps (on), or ends it: the steps
    // Export video: (options { size: 'WxH', fps, pipeline }) -> export id; its state.
    exportVideo: (options) => page.videoExport.start(options),
    cancelExport: () => page.videoExport.cancel(),
    get videoExport() {
      return page.videoExport.snapshot();
    },
  };
}
