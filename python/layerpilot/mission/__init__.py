"""The mission core: one pipeline (``pipeline.MissionPipeline``) over the transport-free step objects
(pilot, map service, depth service) and the scripted flight patterns. It knows no bus and no simulator:
live nodes, the lock-step evaluator and replay all drive the same pipeline (the pattern of ETH's
wavemap: one pipeline, several drivers); the mission file that sets it up is ``layerpilot.missionfile``."""
