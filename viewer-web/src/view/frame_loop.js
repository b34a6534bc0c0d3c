// One requestAnimationFrame callback per page: the 3D view, the plots and the panels' text all
// draw in the same frame, so the browser composites one frame per change instead of one per part
// (on a software-rendered machine each composited frame costs as much as drawing the mesh).
// Parts that draw at a lower rate wait for a later frame; nothing is requested when nothing changed.

/**
 * Something drawn in the page's frame.
 * @typedef {{draw: (now: number) => boolean}} FramePart  draw(now) draws what changed since the
 *   last frame and returns true when it still has something to draw in a later frame (it is
 *   waiting for its rate). `now` is the frame's time, ms (requestAnimationFrame's clock).
 */

export class FrameLoop {
  constructor() {
    /** @type {FramePart[]} */
    this.parts = [];
    this.requested = false;
    this.callback = (/** @type {number} */ now) => this.run(now);
  }

  /** @param {FramePart} part drawn in the order added */
  add(part) {
    this.parts.push(part);
  }

  /** @param {FramePart} part */
  remove(part) {
    const i = this.parts.indexOf(part);
    if (i >= 0) this.parts.splice(i, 1);
  }

  /** Asks for one frame (at most one pending); every part draws what it has then. */
  request() {
    if (this.requested) return;
    this.requested = true;
    requestAnimationFrame(this.callback);
  }

  /** @param {number} now */
  run(now) {
    this.requested = false;
    let again = false;
    for (let i = 0; i < this.parts.length; i++) if (this.parts[i].draw(now)) again = true;
    if (again) this.request();
  }
}

/**
 * True when a part drawn at most `hz` times a second may draw again (2 ms early is on time:
 * animation frames jitter, and waiting one more frame would halve the rate).
 * @param {number} last ms @param {number} now ms @param {number} hz
 */
export function isDue(last, now, hz) {
  return now - last >= 1000 / hz - 2;
}

/**
 * Whether an element is on screen, from an IntersectionObserver; parts skip drawing while their
 * element is scrolled away and draw when it shows again.
 */
export class Visibility {
  /** @param {Element} el @param {() => void} onShow called when the element comes into view */
  constructor(el, onShow) {
    // Visible until told otherwise: the observer's first report comes a frame later.
    this.visible = true;
    this.observer = new IntersectionObserver((entries) => {
      const shown = entries[entries.length - 1].isIntersecting;
      const was = this.visible;
      this.visible = shown;
      if (shown && !was) onShow();
    });
    this.observer.observe(el);
  }

  dispose() {
    this.observer.disconnect();
  }
}
