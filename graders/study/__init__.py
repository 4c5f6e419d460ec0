"""Study tools a learner runs: `progress`, `drill`, `mock`, `srs`, `cards`, `deck`, `reference`, `home`,
and `lab` (`make lab`). Never used while grading."""
