"""The mission core: transport-free step objects (pilot, map service, depth service), the typed
mission file, and scripted flight patterns. Live nodes and the lock-step evaluator drive the same
objects (the pattern of ETH's wavemap: one pipeline, several drivers)."""
