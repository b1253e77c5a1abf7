"""The parts of the loop (:class:`app.pipeline.Pipeline`), one concept each: where the stage jobs run and
how they are timed (``stages``), the camera frames' detector and fusion jobs (``fusion``), autonomy (route
following, go-to, exploration: ``autonomy``) and the run's metrics against ground truth (``metrics``).
The pipeline itself stays in ``app/pipeline.py``."""
