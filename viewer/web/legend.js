// The displacement colours: a perceptual colour map, the scale it spans (a
// decaying peak-hold) and the sentences on the page that say what that scale
// and the panel's "max now" each are, since the two numbers usually differ.

import * as THREE from 'three';

export const MIN_SCALE_M = 0.0005;   // the colour scale never goes below 0.5 mm
export const SCALE_HALF_LIFE_S = 3;  // then follows the peak, decaying
const MM_PER_M = 1000;

// Viridis, 6 stops, for |u| / scale in [0, 1]. The stops are sRGB; vertex
// colours are linear in three.js, so the mesh uses a linearised copy and the
// legend bar (a 2D canvas) the sRGB one.
const VIRIDIS = [[0.267, 0.005, 0.329], [0.254, 0.265, 0.530], [0.164, 0.471, 0.558],
                 [0.134, 0.659, 0.518], [0.478, 0.821, 0.318], [0.993, 0.906, 0.144]];
const VIRIDIS_LINEAR = VIRIDIS.map((rgb) => new THREE.Color().setRGB(...rgb, THREE.SRGBColorSpace).toArray());

/** Writes the colour of t in [0, 1] (clamped) to out[offset .. offset + 2]. */
export function colourAt(t, out, offset, stops = VIRIDIS_LINEAR) {
  const x = Math.min(Math.max(t, 0), 1) * (stops.length - 1);
  const i = Math.min(Math.floor(x), stops.length - 2), f = x - i;
  for (let c = 0; c < 3; ++c) out[offset + c] = stops[i][c] * (1 - f) + stops[i + 1][c] * f;
}

export function drawLegendBar(bar) {
  const g = bar.getContext('2d'), rgb = [0, 0, 0];
  for (let x = 0; x < bar.width; ++x) {
    colourAt(x / (bar.width - 1), rgb, 0, VIRIDIS);
    g.fillStyle = `rgb(${rgb.map((v) => Math.round(255 * v)).join(',')})`;
    g.fillRect(x, 0, 1, bar.height);
  }
}

/**
 * The top of the colour scale, m: it follows a new peak up at once and then
 * halves every SCALE_HALF_LIFE_S, never below MIN_SCALE_M, so that a release
 * fades rather than flashes and a small press still has colours.
 */
export class PeakHoldScale {
  constructor() { this.reset(); }
  reset() { this.peak = { value: 0, time_s: 0 }; }
  /** The scale for a frame whose largest displacement is max_m, at now_s. */
  update(max_m, now_s) {
    const decayed = this.peak.value * Math.pow(0.5, (now_s - this.peak.time_s) / SCALE_HALF_LIFE_S);
    if (max_m >= decayed) this.peak = { value: max_m, time_s: now_s };
    return Math.max(MIN_SCALE_M, Math.max(max_m, decayed));
  }
}

export const mm = (metres) => `${(metres * MM_PER_M).toFixed(2)} mm`;

/** The plain-language meaning of the legend's top value and of "max now". */
export function legendMeaning() {
  return `Colours show the true displacement, from 0 to the peak-hold value at the bar's right: ` +
    `it jumps up to each new largest displacement, then halves every ${SCALE_HALF_LIFE_S} s ` +
    `(never below ${mm(MIN_SCALE_M)}), so colours fade after a release. ` +
    `"max now" is the largest displacement in the frame on screen, so it is at most the peak-hold value ` +
    `and falls at once when the tool lets go.`;
}
