"""The test suite: one package per package of the code (tests/evaluate/ tests src/cornell_harness/evaluate/, ...);
shared helpers (user renderers, report fixtures, the mutant catalogue) at this level, imported as ``tests.*``."""
