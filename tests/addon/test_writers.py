"""The add-on writes each core target through its writer, picked from one table: the job holds no
branch on the kind of output."""
import inspect

from radiosity_baker.addon import job, writers
from radiosity_baker.core.settings import TARGET_OUTPUTS, TARGETS
from radiosity_baker.core.targets import TARGETS as CORE_TARGETS


def test_every_target_choice_has_a_writer_for_each_of_its_core_targets():
    assert set(TARGET_OUTPUTS) == set(TARGETS)
    for names in TARGET_OUTPUTS.values():
        for name in names:
            assert name in CORE_TARGETS and name in writers.WRITERS


def test_the_job_holds_no_branch_on_the_kind_of_output():
    source = inspect.getsource(job)
    for name in (*TARGETS, *CORE_TARGETS):
        assert f'"{name}"' not in source and f"'{name}'" not in source
    for word in ("lightmap", "color_attribute", "animation.prepare"):
        assert word not in source
