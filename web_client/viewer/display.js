// The view's canvas: each decoded frame drawn pixel for pixel (CSS stretches the canvas to its
// box), and latency hiding (reproject.js): until the frame of the newest pose arrives, the shown
// frame re-projected to that pose as a CSS transform of the canvas, with the frame's nearest edge
// continued on a small canvas behind it where it no longer covers the box (never black). Where the
// frame carries a depth grid (Frame.depth_grid) and WebGL2 is there, a canvas over the view draws
// the frame warped by its depth as a mesh (depth_warp.js, warp_gl.js): parallax for a step
// sideways; the plane's picture shows only where the mesh does not reach.

import { warpTriangles, warpVertices } from './depth_warp.js';
import { applyHomography, cssTransform, edgeFill, reprojection } from './reproject.js';
import { WarpGl } from './warp_gl.js';

const samePose = (a, b) =>
  a.fovDeg === b.fovDeg && a.position.every((v, i) => v === b.position[i]) && a.orientation.every((v, i) => v === b.orientation[i]);

export class ViewDisplay {
  // canvas: the view; backdrop: a canvas under it (the edge fill), or null for none.
  constructor(canvas, backdrop) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d', { alpha: false });
    this.backdrop = { el: backdrop, ctx: null, out: null, small: null, smallCtx: null, src: null, stale: true };
    // The depth warp: its overlay canvas and drawer (made with the first grid), the shown frame's
    // grid (null: none yet, or the frame has none), and whether WebGL2 failed (the plane then).
    this.warp = { el: null, gl: null, grid: null, failed: false };
  }

  // Draws a VideoFrame (the caller closes it); the backing store follows the stream's size.
  draw(frame) {
    const w = frame.displayWidth;
    const h = frame.displayHeight;
    const c = this.canvas;
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    this.ctx.drawImage(frame, 0, 0, w, h);
    this.backdrop.stale = true; // a new frame to continue around the re-projected one
    this.warp.grid = null; // this frame's grid comes after it (setDepthGrid)
    if (this.warp.el) this.warp.el.hidden = true;
    return { width: w, height: h };
  }

  // The shown frame's depth grid (depth_warp.js depthGridOf), or null: the next reproject() warps
  // the frame by it. Returns whether the warp can draw (WebGL2 there).
  setDepthGrid(grid) {
    const wp = this.warp;
    wp.grid = grid;
    if (!grid || wp.failed) return false;
    try {
      if (!wp.gl) {
        wp.el = document.createElement('canvas');
        wp.el.style.cssText = 'position:absolute;inset:0;width:100%;height:100%;pointer-events:none';
        wp.el.setAttribute('aria-hidden', 'true');
        wp.el.hidden = true;
        this.canvas.after(wp.el);
        wp.gl = new WarpGl(wp.el);
      }
      wp.gl.setFrame(this.canvas, this.canvas.width, this.canvas.height);
      return true;
    } catch (e) {
      console.warn('catgs: no depth warp (the plane re-projection stays):', e);
      wp.failed = true;
      if (wp.el) wp.el.remove();
      wp.el = null;
      wp.gl = null;
      return false;
    }
  }

  // The shown frame as it was drawn (a new session's first frame replaces it).
  clearTransform() {
    this.canvas.style.transform = '';
  }

  // Shows the frame of pose `from` re-projected to pose `to`, `depthOf()` the scene's depth along
  // the view (asked only when the poses differ); none when they are the same pose, when `from` is
  // unknown, or when a corner would fall behind the new camera (a large turn: better the plain
  // frame).
  reproject(from, to, depthOf) {
    const c = this.canvas;
    const w = c.width;
    const h = c.height;
    let transform = '';
    let shown = null; // the homography shown
    const moved = from && to && w > 0 && h > 0 && !samePose(from, to);
    const depth = moved ? depthOf() : 0;
    if (moved) {
      const H = reprojection(from, to, depth, w, h);
      const corners = [[0, 0], [w, 0], [0, h], [w, h]].map(([x, y]) => applyHomography(H, x, y));
      if (corners.every((p) => p !== null)) {
        transform = cssTransform(H, w, h, c.clientWidth, c.clientHeight);
        shown = H;
      }
    }
    if (c.style.transform !== transform) c.style.transform = transform;
    this._fillBackdrop(shown);
    this._drawWarp(moved ? from : null, to, depth);
  }

  // The frame warped by its depth grid over the view (depth_warp.js), vertices without a surface
  // at the plane's `depth`; hidden when the poses are the same or there is no grid.
  _drawWarp(from, to, depth) {
    const wp = this.warp;
    if (!wp.el) return;
    if (!from || !wp.grid || !wp.gl) {
      wp.el.hidden = true;
      return;
    }
    const w = this.canvas.width;
    const h = this.canvas.height;
    const verts = warpVertices(from, to, wp.grid, depth, w, h);
    wp.gl.draw(verts, warpTriangles(wp.grid, verts));
    wp.el.hidden = false;
  }

  // Where the re-projected frame no longer covers the box (a turn or pan uncovers an edge, a
  // zoom-out all four): the frame's nearest edge continued (reproject.js edgeFill). The backdrop
  // is 256 pixels across at most (about 1 ms a camera move), stretched by CSS to the box.
  _fillBackdrop(H) {
    const b = this.backdrop;
    if (!b.el) return;
    if (!H) {
      b.el.hidden = true;
      return;
    }
    const w = this.canvas.width;
    const h = this.canvas.height;
    const k = Math.min(1, 256 / Math.max(w, h));
    const bw = Math.max(1, Math.round(w * k));
    const bh = Math.max(1, Math.round(h * k));
    if (!b.ctx || b.el.width !== bw || b.el.height !== bh) {
      b.el.width = bw;
      b.el.height = bh;
      b.ctx = b.ctx || b.el.getContext('2d');
      b.out = b.ctx.createImageData(bw, bh);
      b.stale = true;
    }
    if (b.stale) this._shrinkFrame(bw, bh);
    if (edgeFill(H, w, h, b.src, b.out)) b.ctx.putImageData(b.out, 0, 0);
    b.el.hidden = false;
  }

  // The shown frame at the backdrop's size, read once per frame (the canvas holds it).
  _shrinkFrame(bw, bh) {
    const b = this.backdrop;
    if (!b.small) {
      b.small = document.createElement('canvas');
      b.smallCtx = b.small.getContext('2d', { willReadFrequently: true });
    }
    b.small.width = bw;
    b.small.height = bh;
    b.smallCtx.drawImage(this.canvas, 0, 0, bw, bh);
    b.src = b.smallCtx.getImageData(0, 0, bw, bh);
    b.stale = false;
  }
}
