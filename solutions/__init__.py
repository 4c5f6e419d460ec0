"""From-scratch reference solutions, one module per chapter topic."""
