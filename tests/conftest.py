"""Test-suite settings: hypothesis runs derandomised, so a CI run explores the same
examples as the developer's run (the properties still cover many random kernels; new
ones are searched for by running with HYPOTHESIS_PROFILE=explore)."""
import os

from hypothesis import settings

settings.register_profile("millflow", derandomize=True, deadline=None)
settings.register_profile("explore", derandomize=False, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "millflow"))
