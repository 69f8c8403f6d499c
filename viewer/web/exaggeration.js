// Deformation exaggeration: the drawn surface is rest + factor × displacement
// (millimetres on a 20 cm organ are hard to see), while colours, numbers,
// tools and forces stay true. The factor comes from ?exaggerate=N and the
// buttons of the panel; the page always says which factor is in use.

export const EXAGGERATION_FACTORS = [1, 5, 20];
export const EXAGGERATION_PARAMETER = 'exaggerate';

/**
 * The factor a URL parameter asks for: { factor, warning }. No parameter is
 * ×1; a value that is not one of EXAGGERATION_FACTORS is ×1 too, with a
 * warning sentence for the page (a typo must not silently exaggerate, nor
 * stop the page).
 */
export function parseExaggeration(text) {
  if (text === null) return { factor: 1, warning: '' };
  const digits = /^\s*[x×]?(\d+)\s*$/i.exec(text);  // 5, x5 or ×5
  const factor = digits ? Number(digits[1]) : NaN;
  if (EXAGGERATION_FACTORS.includes(factor)) return { factor, warning: '' };
  const offered = EXAGGERATION_FACTORS.map((f) => `×${f}`).join(', ');
  return { factor: 1, warning: `?${EXAGGERATION_PARAMETER}=${text} is not one of ${offered}: shape drawn true (×1).` };
}

/** What the page says about the factor in use. */
export function describeExaggeration(factor) {
  return factor === 1
    ? 'shape true (×1); colours and numbers true'
    : `shape ×${factor} exaggerated; colours, numbers and tools true`;
}

/**
 * Buttons for the factors in `container`, the sentence in `stateLine`, the
 * warning (if any) in `warningLine`; calls onChange(factor) when a button
 * is pressed and keeps the address bar's parameter in step, so a reload or a
 * shared link shows the same factor.
 */
export function createExaggerationControl({ container, stateLine, warningLine, initial, onChange }) {
  const buttons = EXAGGERATION_FACTORS.map((factor) => {
    const button = document.createElement('button');
    button.type = 'button';
    button.textContent = `×${factor}`;
    button.dataset.factor = String(factor);
    button.addEventListener('click', () => select(factor, true));
    return button;
  });
  container.append(...buttons);
  warningLine.textContent = initial.warning;
  warningLine.hidden = initial.warning === '';

  function select(factor, byUser) {
    for (const b of buttons) b.classList.toggle('active', Number(b.dataset.factor) === factor);
    stateLine.textContent = describeExaggeration(factor);
    if (!byUser) return;
    warningLine.hidden = true;
    const url = new URL(location.href);
    if (factor === 1) url.searchParams.delete(EXAGGERATION_PARAMETER);
    else url.searchParams.set(EXAGGERATION_PARAMETER, String(factor));
    history.replaceState(null, '', url);
    onChange(factor);
  }
  select(initial.factor, false);
}
