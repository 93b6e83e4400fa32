"""Python client of the bouncewear service (docs/contract.md of the repository).

    from bouncewear import Client

    client = Client("http://127.0.0.1:8080")
    job = client.submit({"devices": 100, "operations": 1000, "seed": 1})
    job.wait()
    curve = job.distribution("total_bounce_s")   # a pandas.DataFrame, one row per bin
"""

from .client import BouncewearError, Client, FieldError, Job, JobFailed, Schedule

__all__ = ["BouncewearError", "Client", "FieldError", "Job", "JobFailed", "Schedule"]
__version__ = "0.1.0"
