// ESLint's flat config for the package (run by `npm test` before the tests): the recommended rules plus a
// few that keep modules small and failures loud.
import js from '@eslint/js';
import globals from 'globals';

export default [
  { ignores: ['node_modules/', 'types/'] },
  js.configs.recommended,
  {
    files: ['**/*.js', '**/*.mjs'],
    languageOptions: {
      ecmaVersion: 2024,
      sourceType: 'module',
      globals: { ...globals.browser, ...globals.node },
    },
    rules: {
      'no-unused-vars': ['error', { argsIgnorePattern: '^_', caughtErrors: 'none' }],
      'no-var': 'error',
      'prefer-const': 'error',
      eqeqeq: ['error', 'always'],
      'max-lines': ['error', { max: 900, skipBlankLines: true, skipComments: true }],
      'max-lines-per-function': ['warn', { max: 60, skipBlankLines: true, skipComments: true }],
    },
  },
  {
    files: ['test/**/*.mjs'],
    rules: { 'max-lines-per-function': 'off', 'max-lines': 'off' },
  },
];
