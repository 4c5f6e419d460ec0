"""Running learner code and coursework: the shell grader's `runner` (check_file, limits, workers),
`extract`, `worker`, graded mode's `isolation` (judge side) and `learner` (learner side), `batch`,
`release` / Gradescope, `fairness`. The only package that runs learner code in another process."""
