// ESLint flat config: js/ runs in the browser as ES modules, test/ under `node --test`.
import js from '@eslint/js';
import globals from 'globals';

export default [
  {ignores: ['node_modules/']},
  js.configs.recommended,
  {files: ['js/**/*.js'], languageOptions: {globals: globals.browser}},
  {files: ['test/**/*.js', 'eslint.config.js'], languageOptions: {globals: globals.node}},
];
