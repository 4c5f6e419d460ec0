"""The engine: an exercise as data (`engine`), running one attempt safely (`sandbox`), output checks
(`convert`), metrics (`compare`), results (`report`) and the chapter table (`chapters`). Ships to learners.
Imports only `graders.kit` (see `graders.layers`)."""
