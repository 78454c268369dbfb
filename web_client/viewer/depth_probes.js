// The server's depth probe (DepthRequest -> DepthResult): what lies under a pixel of a view.
// Each request waits for its answer by id; answers of a session that ended never come, so their
// waits end with it.

export class DepthProbes {
  // send(bytes) -> bool (false: not connected); protocol() -> the protocol (protocol.js).
  constructor(send, protocol) {
    this.send = send;
    this.protocol = protocol;
    this.waiting = new Map(); // request_id -> { resolve, reject }
    this.nextId = 1;
  }

  // What lies under pixel (x, y) of a width x height view of `pose`: a Promise of the
  // DepthResult; rejected when it cannot be sent or the session ends first.
  request(pose, width, height, x, y) {
    const requestId = this.nextId++;
    return new Promise((resolve, reject) => {
      this.waiting.set(requestId, { resolve, reject });
      if (!this.send(this.protocol().encodeDepthRequest({ requestId, x, y, width, height, pose }))) {
        this.waiting.delete(requestId);
        reject(new Error('not connected'));
      }
    });
  }

  // A DepthResult: its request's wait ends with `result` (the message as the caller wants it).
  answer(msg, result) {
    const w = this.waiting.get(msg.request_id);
    if (!w) return;
    this.waiting.delete(msg.request_id);
    w.resolve(result);
  }

  rejectAll() {
    for (const w of this.waiting.values()) w.reject(new Error('the session ended'));
    this.waiting.clear();
  }
}
