"""The application layer: inputs and settings in one place, every command a slice of ``build``.

- :mod:`vid2sim.app.settings`: the typed :class:`~vid2sim.app.settings.Settings` tree, composed
  of the stages' own frozen config classes;
- :mod:`vid2sim.app.inputs`: the :class:`~vid2sim.app.inputs.Inputs` record (video, GPS, map,
  camera, detections, keyframes, and the GPS time base) and its validation;
- :mod:`vid2sim.app.loaders`: the one place each shared thing is loaded (camera fitted to the
  frames, detector, imported boxes, GPS trace with its offset);
- :mod:`vid2sim.app.tracking` (``detect``, ``track``: the detection stack only),
  :mod:`vid2sim.app.commands`, :mod:`vid2sim.app.build`, :mod:`vid2sim.app.batch`: what each
  CLI command runs.

Imports run one way: ``cli -> app -> geo/detect/export/evaluate -> scenario, camera, records,
tables, fileio, errors``. No stage imports the application layer.
"""
