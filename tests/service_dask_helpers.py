"""A task function that takes longer than the Dask test's timeout."""

import time


def sleepy(task) -> dict:
    time.sleep(5)
    return {}
