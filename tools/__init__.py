"""Developer tools, not shipped to learners (`make clean-notebooks`)."""
