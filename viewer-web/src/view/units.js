// What a session's numbers are in: millimetres and newtons when its scene declares them
// (idms.v1.Units: mm per model unit, N per model force unit; the API gives them as each session's
// "units"), else the model's own units, labelled as such (display.json's "unit"). Every page that
// shows a length or a force of a session converts and labels it through one of these.
import { display } from './display.js';

export class Units {
  /**
   * @param {{mm_per_unit?: number, newtons_per_force_unit?: number, mmPerUnit?: number | null,
   *   newtonsPerForceUnit?: number | null} | null | undefined} [declared] the API's (snake case) or
   *   the Welcome's scene's (camel case) units
   */
  constructor(declared) {
    const mm = Number(declared?.mm_per_unit ?? declared?.mmPerUnit ?? NaN);
    const n = Number(declared?.newtons_per_force_unit ?? declared?.newtonsPerForceUnit ?? NaN);
    /** Factors from model units to what is shown: 1 where nothing is declared. */
    this.lengthScale = mm > 0 ? mm : 1;
    this.forceScale = n > 0 ? n : 1;
    this.length = mm > 0 ? 'mm' : display.unit.length;
    this.force = n > 0 ? 'N' : display.unit.force;
    this.stiffness = mm > 0 && n > 0 ? 'N/mm' : display.unit.stiffness;
    this.stiffnessScale = mm > 0 && n > 0 ? n / mm : 1;
  }

  /** A length in model units, shown. @param {number} v */
  len(v) {
    return v * this.lengthScale;
  }

  /** A force in model force units, shown. @param {number} v */
  frc(v) {
    return v * this.forceScale;
  }

  /** The same units (nothing to redraw). @param {Units} other */
  equals(other) {
    return this.lengthScale === other.lengthScale && this.forceScale === other.forceScale
      && this.length === other.length && this.force === other.force;
  }
}

/** The model's own units: what a page shows until it knows better. */
export const kModelUnits = new Units(null);
