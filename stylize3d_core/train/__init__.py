"""Training data for the stylization model (docs/architecture.md, "Pipeline stages", training).

``data``: training samples (pseudo novel views rendered from a photo's LDI, and
procedural scenes with true novel views); ``cache``: their disk cache
(``build_dataset``, ``TrainDataset``); ``styles``: the
style-image bank; ``procedural``: the analytic ray caster and random depth maps;
``textures``: procedural textures; ``photos``: the training photos and their
licences.
"""
