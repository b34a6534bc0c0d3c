// A session's grade against its scene's limits, in words: the server's "grade" on each session
// (null when the scene names no limit, else {passed, checks: [{figure, limit, value, passed}]}).
// The sessions' table, a session's page, the comparison and the report all say it the same way.
import { display } from '../view/display.js';
import { h, fixed } from './dom.js';

/** What each graded figure is called and how it is written. */
const kFigures = /** @type {Record<string, {name: string, unit: string, digits: number}>} */ ({
  peak_force: { name: 'peak force', unit: display.unit.force, digits: 2 },
  contact_time_s: { name: 'time in contact', unit: 's', digits: 1 },
  path_length: { name: 'path length', unit: display.unit.length, digits: 2 },
  force_limit_hits: { name: 'force-limit hits', unit: '', digits: 0 },
});

/**
 * @typedef {{figure: string, limit: number, value: number, passed: boolean}} Check
 * @typedef {{passed: boolean, checks: Check[]} | null | undefined} Grade
 */

/** One check in words, e.g. "peak force 2.10 > 1.50 model force units". @param {Check} c */
export function checkWords(c) {
  const f = kFigures[c.figure] ?? { name: c.figure.replace(/_/g, ' '), unit: '', digits: 2 };
  return `${f.name} ${fixed(c.value, f.digits)} ${c.passed ? '≤' : '>'} ${fixed(c.limit, f.digits)}${f.unit ? ` ${f.unit}` : ''}`;
}

/**
 * The grade in a word and the checks in a sentence: {word: 'passed' | 'failed' | '', detail}.
 * @param {Grade} grade
 */
export function gradeWords(grade) {
  if (!grade || !Array.isArray(grade.checks) || grade.checks.length === 0) return { word: '', detail: 'not graded (the scene names no limits)' };
  const failed = grade.checks.filter((c) => !c.passed);
  const word = grade.passed ? 'passed' : 'failed';
  const detail = failed.length
    ? `failed ${failed.length} of ${grade.checks.length}: ${failed.map(checkWords).join('; ')}`
    : `passed all ${grade.checks.length}: ${grade.checks.map(checkWords).join('; ')}`;
  return { word, detail };
}

/** A badge: "passed" or "failed", the checks in its title; nothing when not graded. @param {Grade} grade */
export function gradeBadge(grade) {
  const { word, detail } = gradeWords(grade);
  if (!word) return null;
  return h('span', { class: `badge grade ${word}`, title: detail, 'aria-label': `grade: ${detail}`, text: word });
}

/**
 * Every check as a list item marked passed or failed (a session's page, the report).
 * @param {Grade} grade
 */
export function gradeList(grade) {
  const { word, detail } = gradeWords(grade);
  if (!word) return h('p', { class: 'muted grade-none', text: 'Not graded: the scene names no limits.' });
  return h('div', { class: 'grade-block' }, [
    h('p', {}, ['Graded against the scene\'s limits: ', gradeBadge(grade), ` ${detail.split(':')[0]}`]),
    h('ul', { class: 'grade-checks' }, (grade?.checks ?? []).map((c) =>
      h('li', { class: c.passed ? 'passed' : 'failed' }, [h('span', { class: 'mark-word', text: c.passed ? '✓ within' : '✗ beyond' }), ' ', checkWords(c)]))),
  ]);
}
