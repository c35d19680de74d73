// The viewer's lint (issue 37): ESLint's recommended rules plus unused variables, over the
// viewer's modules (browser globals) and its decode worker (worker globals). Run by .ci/run:
//   (cd web && npm ci && npx eslint .)
import js from "@eslint/js";
import globals from "globals";

export default [
  { ignores: ["node_modules/"] },
  js.configs.recommended,
  {
    files: ["**/*.js"],
    languageOptions: {
      ecmaVersion: 2024,
      sourceType: "module",
      globals: { ...globals.browser },
    },
    rules: {
      "no-unused-vars": ["error", { args: "after-used", caughtErrors: "none" }],
    },
  },
  {
    files: ["decode-worker.js"],
    languageOptions: { globals: { ...globals.worker } },
  },
];
