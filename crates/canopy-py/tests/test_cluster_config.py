"""The cloud cluster configuration in docs/cluster/ is one Ray accepts: it is checked
against Ray's own cluster schema (it is never launched from here)."""

from pathlib import Path

import pytest

yaml = pytest.importorskip("yaml")
pytest.importorskip("ray")

CONFIG = Path(__file__).resolve().parents[3] / "docs" / "cluster" / "aws.yaml"


def test_the_documented_cluster_configuration_follows_rays_schema():
    from ray.autoscaler._private.util import prepare_config, validate_config

    config = yaml.safe_load(CONFIG.read_text())
    validate_config(prepare_config(config))  # raises on anything Ray's schema refuses
    assert config["available_node_types"]["head"]["resources"] == {"CPU": 0}
    assert any("canopy_rt" in c for c in config["setup_commands"])


def test_the_schema_check_refuses_a_broken_configuration():
    from ray.autoscaler._private.util import prepare_config, validate_config

    config = yaml.safe_load(CONFIG.read_text())
    config["available_node_types"]["render"]["max_workers"] = "many"
    with pytest.raises(Exception, match="'many' is not of type 'integer'"):
        validate_config(prepare_config(config))
