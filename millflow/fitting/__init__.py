"""Parameter estimation for population-balance models of milling (issue 6)."""
