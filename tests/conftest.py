"""Shared test set-up.

- Seeds: every random test takes `rng` (or `seed`); the seed comes from MOP_TEST_SEED
  (default 12345) and is printed in the header so a failure can be replayed.
"""
import os

import numpy as np
import pytest

SEED = int(os.environ.get("MOP_TEST_SEED", "12345"))


def pytest_report_header(config):
    return f"MOP_TEST_SEED={SEED} (set the variable to replay another seed)"


@pytest.fixture
def seed() -> int:
    return SEED


@pytest.fixture
def rng(seed) -> np.random.Generator:
    return np.random.default_rng(seed)
