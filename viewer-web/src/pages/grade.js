// A session's grade against its scene's limits, in words: the server's "grade" on each session
// (null when the scene names no limit, else {passed, checks: [{figure, limit, value, passed}]}).
// The sessions' table, a session's page, the comparison and the report all say it the same way.
import { Units, kModelUnits } from '../view/units.js';
import { h, fixed } from './dom.js';

/**
 * What each graded figure is called, how it is written, and in what (the session's units: the
 * limits are in model units, as the figures).
 * @param {string} figure @param {Units} u
 */
function figureOf(figure, u) {
  switch (figure) {
    case 'peak_force': return { name: 'peak force', unit: u.force, digits: 2, scale: u.forceScale };
    case 'contact_time_s': return { name: 'time in contact', unit: 's', digits: 1, scale: 1 };
    case 'path_length': return { name: 'path length', unit: u.length, digits: 2, scale: u.lengthScale };
    case 'force_limit_hits': return { name: 'force-limit hits', unit: '', digits: 0, scale: 1 };
    default: return { name: figure.replace(/_/g, ' '), unit: '', digits: 2, scale: 1 };
  }
}

/**
 * @typedef {{figure: string, limit: number, value: number, passed: boolean}} Check
 * @typedef {{passed: boolean, checks: Check[]} | null | undefined} Grade
 */

/** One check in words, e.g. "peak force 2.10 > 1.50 model force units". @param {Check} c @param {Units} [u] */
export function checkWords(c, u = kModelUnits) {
  const f = figureOf(c.figure, u);
  return `${f.name} ${fixed(c.value * f.scale, f.digits)} ${c.passed ? '≤' : '>'} ${fixed(c.limit * f.scale, f.digits)}${f.unit ? ` ${f.unit}` : ''}`;
}

/**
 * The grade in a word and the checks in a sentence: {word: 'passed' | 'failed' | '', detail}.
 * @param {Grade} grade @param {Units} [u]
 */
export function gradeWords(grade, u = kModelUnits) {
  if (!grade || !Array.isArray(grade.checks) || grade.checks.length === 0) return { word: '', detail: 'not graded (the scene names no limits)' };
  const failed = grade.checks.filter((c) => !c.passed);
  const word = grade.passed ? 'passed' : 'failed';
  const detail = failed.length
    ? `failed ${failed.length} of ${grade.checks.length}: ${failed.map((c) => checkWords(c, u)).join('; ')}`
    : `passed all ${grade.checks.length}: ${grade.checks.map((c) => checkWords(c, u)).join('; ')}`;
  return { word, detail };
}

/** A badge: "passed" or "failed", the checks in its title; nothing when not graded. @param {Grade} grade @param {Units} [u] */
export function gradeBadge(grade, u = kModelUnits) {
  const { word, detail } = gradeWords(grade, u);
  if (!word) return null;
  return h('span', { class: `badge grade ${word}`, title: detail, 'aria-label': `grade: ${detail}`, text: word });
}

/**
 * Every check as a list item marked passed or failed (a session's page, the report).
 * @param {Grade} grade @param {Units} [u]
 */
export function gradeList(grade, u = kModelUnits) {
  const { word, detail } = gradeWords(grade, u);
  if (!word) return h('p', { class: 'muted grade-none', text: 'Not graded: the scene names no limits.' });
  return h('div', { class: 'grade-block' }, [
    h('p', {}, ['Graded against the scene\'s limits: ', gradeBadge(grade, u), ` ${detail.split(':')[0]}`]),
    h('ul', { class: 'grade-checks' }, (grade?.checks ?? []).map((c) =>
      h('li', { class: c.passed ? 'passed' : 'failed' }, [h('span', { class: 'mark-word', text: c.passed ? '✓ within' : '✗ beyond' }), ' ', checkWords(c, u)]))),
  ]);
}
