"""Testing driving functions on recorded scenarios: built-in ACC, AEB and LKA functions, user
policies, a camera sensor model, scenario variations and the campaign of ``vid2sim
test-policy`` (episodes in ``vid2sim/Replay-v0``, ``results.csv``, ``summary.html``)."""
