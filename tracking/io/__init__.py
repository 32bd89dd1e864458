"""File formats the tracker reads and writes (docs/FILES.md): one module per format.

``recording`` (recording folders: videos or image folders per camera, meta.yaml, time stamps),
``trc``, ``c3d``, ``csv_tables`` (joint-angle and marker-status CSV), ``opensim_mot``, ``bvh``,
``detections`` (2D detections CSV). Readers check what they read and raise one-line errors
(docs/INPUTS.md).
"""
