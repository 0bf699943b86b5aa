// Renders the equations pymdownx.arithmatex marks (generic mode: \( \) inline, \[ \] display)
// with the KaTeX copy in docs/vendor/katex (npm package katex 0.19.1, MIT licence; its fonts as
// woff2 only), so the site needs no network. Runs on every page Material loads, instant
// navigation included.
document$.subscribe(({ body }) => {
  renderMathInElement(body, {
    delimiters: [
      { left: "\\(", right: "\\)", display: false },
      { left: "\\[", right: "\\]", display: true }
    ],
    // code blocks keep their text as written
    ignoredClasses: ["highlight"],
    throwOnError: false
  });
});
