"""The physics core: dynamics, estimation, scheduling, guidance and the closed loop.

Pure functions and small frozen types on the typed parameters of
:mod:`cwrend_cli.physics.params`; no configuration models, no files, no
console. Nothing here imports anything outside :mod:`cwrend_cli.physics`
(``tests/test_layers.py`` walks the imports and fails otherwise).
Units everywhere (the paper's, Table 1): km, s, km/s, km/s², rad/s.
"""
