// WebGL2 helpers the page's two drawers share (warp_gl.js: the depth warp's mesh; xr_gl.js: a VR
// frame's eyes): a linked program, and the frame's texture sampled as a browser samples a
// stretched canvas (linear filtering, clamped to the edge).

function shader(gl, type, source, who) {
  const s = gl.createShader(type);
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`${who} shader: ${gl.getShaderInfoLog(s)}`);
  return s;
}

// The program of `vertex` and `fragment` (GLSL ES 3.00 sources); throws naming `who` and the
// compiler's or linker's log.
export function linkProgram(gl, vertex, fragment, who) {
  const p = gl.createProgram();
  gl.attachShader(p, shader(gl, gl.VERTEX_SHADER, vertex, who));
  gl.attachShader(p, shader(gl, gl.FRAGMENT_SHADER, fragment, who));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`${who} program: ${gl.getProgramInfoLog(p)}`);
  return p;
}

// A new texture, bound, with linear filtering and clamp-to-edge wrapping.
export function frameTexture(gl) {
  const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, t);
  for (const [k, v] of [
    [gl.TEXTURE_MIN_FILTER, gl.LINEAR],
    [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
    [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE],
    [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE],
  ])
    gl.texParameteri(gl.TEXTURE_2D, k, v);
  return t;
}
