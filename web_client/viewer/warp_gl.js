// Draws the depth warp's mesh (depth_warp.js) with WebGL2 on a transparent canvas over the view:
// the frame as a texture (linear filtering, clamp to edge, as a browser samples a stretched
// canvas), each vertex at its clip position (x, y from the new camera's image point, w = X2h.z so
// the interpolation of the frame's coordinates is perspective-correct), and a depth test on the
// inverse depth (nearest wins). Where no triangle reaches (past the frame's moved edge) the canvas
// stays clear and the view's own re-projection (display.js) shows through.

import { frameTexture, linkProgram } from './gl_program.js';

const VERTEX = `#version 300 es
in vec4 clip;
in vec2 uv;
out vec2 v_uv;
void main() { v_uv = uv; gl_Position = clip; }`;

const FRAGMENT = `#version 300 es
precision highp float;
uniform sampler2D frame;
in vec2 v_uv;
out vec4 colour;
void main() { colour = vec4(texture(frame, v_uv).rgb, 1.0); }`;


export class WarpGl {
  // canvas: the overlay; throws where WebGL2 is not available (the caller keeps the plane then).
  constructor(canvas) {
    const gl = canvas.getContext('webgl2', { alpha: true, premultipliedAlpha: true, antialias: false, depth: true });
    if (!gl) throw new Error('no WebGL2');
    this.canvas = canvas;
    this.gl = gl;
    const p = linkProgram(gl, VERTEX, FRAGMENT, 'depth warp');
    this.program = p;
    this.clipLoc = gl.getAttribLocation(p, 'clip');
    this.uvLoc = gl.getAttribLocation(p, 'uv');
    this.clipBuf = gl.createBuffer();
    this.uvBuf = gl.createBuffer();
    this.indexBuf = gl.createBuffer();
    this.texture = frameTexture(gl);
  }

  // The frame to warp (a canvas or a VideoFrame), width x height pixels: the overlay's size too.
  setFrame(source, width, height) {
    const { gl, canvas } = this;
    if (canvas.width !== width || canvas.height !== height) {
      canvas.width = width;
      canvas.height = height;
    }
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, source);
  }

  // Draws the mesh of `verts` (depth_warp.js warpVertices) and `triangles` (warpTriangles).
  draw(verts, triangles) {
    const { gl, canvas } = this;
    const w = canvas.width;
    const h = canvas.height;
    const n = verts.clipW.length;
    // Window depth 1 - k / z2 with k below the nearest vertex's z2: in [0, 1), nearer smaller.
    let maxInv = 0;
    for (let i = 0; i < n; i++) if (verts.clipW[i] > 1e-9) maxInv = Math.max(maxInv, verts.invZ[i]);
    const k = maxInv > 0 ? 0.999 / maxInv : 0;
    const clip = new Float32Array(4 * n);
    const uv = new Float32Array(2 * n);
    for (let i = 0; i < n; i++) {
      const cw = verts.clipW[i];
      // Clip coordinates whose division by cw gives NDC (x right, y up).
      clip[4 * i] = ((2 * verts.sx[i]) / w - 1) * cw;
      clip[4 * i + 1] = (1 - (2 * verts.sy[i]) / h) * cw;
      clip[4 * i + 2] = (2 * (1 - k * verts.invZ[i]) - 1) * cw;
      clip[4 * i + 3] = cw;
      uv[2 * i] = verts.u[i] / w;
      uv[2 * i + 1] = verts.v[i] / h;
    }
    gl.viewport(0, 0, w, h);
    gl.clearColor(0, 0, 0, 0);
    gl.clearDepth(1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LEQUAL);
    gl.useProgram(this.program);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.clipBuf);
    gl.bufferData(gl.ARRAY_BUFFER, clip, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(this.clipLoc);
    gl.vertexAttribPointer(this.clipLoc, 4, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.uvBuf);
    gl.bufferData(gl.ARRAY_BUFFER, uv, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(this.uvLoc);
    gl.vertexAttribPointer(this.uvLoc, 2, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.indexBuf);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, triangles, gl.DYNAMIC_DRAW);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.drawElements(gl.TRIANGLES, triangles.length, gl.UNSIGNED_INT, 0);
  }

  clear() {
    const { gl } = this;
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  }
}
