"""vid2sim: turn a geotagged dash-cam video into a replayable driving scenario."""

__version__ = "0.1.0"

# The highway-env replay environment, so gymnasium.make("vid2sim/Replay-v0", scenario=...) works
# after `import vid2sim`; the entry point string keeps highway-env unimported until then.
try:
    import gymnasium as _gym

    if "vid2sim/Replay-v0" not in _gym.registry:
        _gym.register(id="vid2sim/Replay-v0", entry_point="vid2sim.export.highway:ReplayEnv")
except ImportError:  # pragma: no cover - gymnasium is a dependency; keep bare imports working
    pass
