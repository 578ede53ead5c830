// ESLint flat config, as web/'s: src/ runs in browsers as ES modules, test/ under `node --test`.
import js from '@eslint/js';
import globals from 'globals';

export default [
  {ignores: ['node_modules/']},
  js.configs.recommended,
  {files: ['src/**/*.js'], languageOptions: {globals: globals.browser}},
  {files: ['test/**/*.js', 'eslint.config.js'], languageOptions: {globals: globals.node}},
];
