// Draws a VR frame's eyes into an XR layer with WebGL2 (issue 94): the decoded frame is one
// texture (both eyes side by side); each eye's viewport is covered by one triangle whose fragment
// shader follows the ray of its display pixel, as the eye looks now, into the frame's image of that
// eye through a homography (xr.js: the plane's, reproject.js reprojectionK, inverted), so a head
// turn moves the picture at the display's rate whatever the network does. Where the ray leaves the
// eye's part of the frame, the nearest pixel of that part (clamped to its edge pixels' centres, so
// linear filtering never blends in the other eye): never black where the frame has pixels.

import { frameTexture, linkProgram } from './gl_program.js';

const VERTEX = `#version 300 es
// One triangle that covers the viewport (clip space -1..3).
void main() {
  vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}`;

const FRAGMENT = `#version 300 es
precision highp float;
uniform sampler2D frame;
uniform mat3 toFrame;   // display pixel (x right, y down, continuous) -> the frame eye's pixel
uniform vec4 viewport;  // this eye's viewport in the framebuffer: x, y (from the bottom), w, h
uniform vec3 eyeRect;   // the eye's part of the frame: first column, width, height (pixels)
uniform vec2 texSize;   // the frame's size, pixels
out vec4 colour;
void main() {
  vec2 p = vec2(gl_FragCoord.x - viewport.x, viewport.y + viewport.w - gl_FragCoord.y);
  vec3 h = toFrame * vec3(p, 1.0);
  // Behind the frame's camera (a turn of nearly 90 degrees within a round trip): the ray's side
  // still says which edge is nearest.
  vec2 e = h.xy / max(h.z, 1e-6);
  e = clamp(e, vec2(0.5), eyeRect.yz - 0.5);
  colour = vec4(texture(frame, vec2(eyeRect.x + e.x, e.y) / texSize).rgb, 1.0);
}`;

// Before the first frame: a plain dark grey, not black (black reads as "broken" in a headset).
const WAITING = [0.12, 0.12, 0.14, 1];


export class EyeDrawer {
  // gl: a WebGL2 context (made xrCompatible: xr.js).
  constructor(gl) {
    this.gl = gl;
    const p = linkProgram(gl, VERTEX, FRAGMENT, 'VR');
    this.program = p;
    this.loc = Object.fromEntries(['frame', 'toFrame', 'viewport', 'eyeRect', 'texSize'].map((n) => [n, gl.getUniformLocation(p, n)]));
    this.vao = gl.createVertexArray(); // no attributes: the vertex shader makes the triangle
    this.texture = frameTexture(gl);
    this.width = 0; // the texture's size (0: no frame yet)
    this.height = 0;
  }

  // The decoded frame (a VideoFrame; the caller closes it): copied into the texture now, so the
  // frame can go back to the decoder at once.
  upload(frame) {
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false); // row 0 of the texture is the image's top
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, frame);
    this.width = frame.displayWidth;
    this.height = frame.displayHeight;
  }

  get hasFrame() {
    return this.width > 0;
  }

  // Begins a display frame on `framebuffer` (the XR layer's; null: the canvas's own) of
  // fbWidth x fbHeight: before the first frame, all of it the waiting colour.
  begin(framebuffer, fbWidth, fbHeight) {
    const gl = this.gl;
    gl.bindFramebuffer(gl.FRAMEBUFFER, framebuffer);
    gl.disable(gl.DEPTH_TEST);
    gl.disable(gl.BLEND);
    gl.disable(gl.SCISSOR_TEST);
    if (!this.hasFrame) {
      gl.viewport(0, 0, fbWidth, fbHeight);
      gl.clearColor(...WAITING);
      gl.clear(gl.COLOR_BUFFER_BIT);
    }
  }

  // One eye: `viewport` ({ x, y, width, height }: XRWebGLLayer.getViewport), `toFrame` (3x3 rows:
  // display pixel -> frame pixel of the eye's part), `eye` ({ x0, width, height }: the eye's part of
  // the frame). Nothing before the first frame (begin cleared it).
  drawEye(viewport, toFrame, eye) {
    if (!this.hasFrame) return;
    const gl = this.gl;
    gl.viewport(viewport.x, viewport.y, viewport.width, viewport.height);
    gl.useProgram(this.program);
    gl.bindVertexArray(this.vao);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.uniform1i(this.loc.frame, 0);
    // GLSL's mat3 is column-major: the rows go in transposed.
    const m = toFrame;
    gl.uniformMatrix3fv(this.loc.toFrame, false, [m[0][0], m[1][0], m[2][0], m[0][1], m[1][1], m[2][1], m[0][2], m[1][2], m[2][2]]);
    gl.uniform4f(this.loc.viewport, viewport.x, viewport.y, viewport.width, viewport.height);
    gl.uniform3f(this.loc.eyeRect, eye.x0, eye.width, eye.height);
    gl.uniform2f(this.loc.texSize, this.width, this.height);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }
}
