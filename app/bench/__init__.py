"""``ocslam bench …`` benchmarks, one module each (``add_arguments`` + ``run``)."""
