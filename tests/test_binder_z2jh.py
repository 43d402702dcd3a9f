"""docker/hub/z2jh-values.yaml: a Zero to JupyterHub configuration the chart and the hub accept.

Helm validates a release's values (the chart's values.yaml with the user's file merged on top)
against the chart's values.schema; here the same merge is checked against a copy of Zero to
JupyterHub 4.4.0's schema (docker/hub/z2jh-4.4.0/, its source and licence in README.md there).
The hub's own settings (hub.config) are checked against the classes they configure: the LTI
authenticator's, JupyterHub's and its Authenticator's traits.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest

from tests.conftest import need

ROOT = Path(__file__).resolve().parents[1]
HUB = ROOT / "docker/hub"
CHART = HUB / "z2jh-4.4.0"


def load_yaml(path: Path):
    """YAML as Helm reads it, but a key given twice in one mapping is an error (Helm keeps the last)."""
    yaml = need("yaml")

    class Strict(yaml.SafeLoader):
        pass

    def mapping(loader, node, deep=False):
        keys = [loader.construct_object(k, deep=deep) for k, _ in node.value]
        twice = {k for k in keys if keys.count(k) > 1}
        if twice:
            raise ValueError(f"{path.name} line {node.start_mark.line + 1}: {sorted(twice)} given twice")
        return loader.construct_mapping(node, deep=deep)

    Strict.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return yaml.load(path.read_text(), Loader=Strict)


def helm_merge(chart: dict, user: dict) -> dict:
    """Helm's coalescing of a user's values onto the chart's: maps merge, a user's null removes a key."""
    out = copy.deepcopy(chart)
    for key, value in user.items():
        if value is None:
            out.pop(key, None)
        elif isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = helm_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def schema_errors(values: dict) -> list[str]:
    jsonschema = need("jsonschema")
    schema = load_yaml(CHART / "values.schema.yaml")
    merged = helm_merge(load_yaml(CHART / "values.yaml"), values)
    validator = jsonschema.Draft7Validator(schema)
    return sorted(f"{'.'.join(map(str, e.absolute_path)) or '(top)'}: {e.message}"
                  for e in validator.iter_errors(merged))


@pytest.fixture(scope="module")
def values() -> dict:
    """The values file with what the install command adds (`--set-file` of the exchange's code)."""
    values = load_yaml(HUB / "z2jh-values.yaml")
    command = re.search(r"--set-file (\S+)=(\S+)", (HUB / "z2jh-values.yaml").read_text())
    assert command, "the install command in z2jh-values.yaml's header passes the exchange's code with --set-file"
    *where, last = command.group(1).split(".")
    node = values
    for key in where:
        node = node[key]
    code = ROOT / command.group(2)
    node[last] = code.read_text() if code.exists() else f"# {command.group(2)}"
    return values


def test_values_pass_the_charts_schema(values):
    assert schema_errors(values) == []


def test_the_schema_check_catches_a_misspelt_or_mistyped_setting(values):
    wrong = copy.deepcopy(values)
    wrong["singleuser"]["memroy"] = wrong["singleuser"].pop("memory")
    wrong["cull"]["timeout"] = "forty minutes"
    errors = schema_errors(wrong)
    assert any(e.startswith("singleuser:") and "'memroy' was unexpected" in e for e in errors), errors
    assert any(e.startswith("cull.timeout:") and "is not of type 'integer'" in e for e in errors), errors


def test_a_key_given_twice_is_an_error(tmp_path):
    twice = tmp_path / "values.yaml"
    twice.write_text("hub:\n  config: {}\nsingleuser: {}\nhub:\n  db: {}\n")
    with pytest.raises(ValueError, match=r"\['hub'\] given twice"):
        load_yaml(twice)


def test_hub_config_names_real_settings_of_the_classes_it_configures(values):
    """Every key under hub.config is a configurable trait of its class, with a value that trait accepts."""
    need("jupyterhub")
    need("ltiauthenticator")
    from jupyterhub.app import JupyterHub
    from jupyterhub.auth import Authenticator
    from jupyterhub.spawner import Spawner
    from ltiauthenticator.lti13.auth import LTI13Authenticator

    config = values["hub"]["config"]
    classes = {"JupyterHub": JupyterHub, "Authenticator": Authenticator, "LTI13Authenticator": LTI13Authenticator,
               "Spawner": Spawner}
    assert set(config) <= set(classes), set(config) - set(classes)
    for name, settings in config.items():
        traits = classes[name].class_traits(config=True)
        unknown = set(settings) - set(traits)
        assert not unknown, f"hub.config.{name}: {sorted(unknown)} are not settings of {classes[name].__name__}"
        for key, value in settings.items():
            traits[key].validate(classes[name].__new__(classes[name]), value)  # raises TraitError on a bad value
    # the chart builds these lists itself (the culler's service and role, hub.services, hub.loadRoles)
    # and then applies hub.config over them: set there, they would drop the culler's
    assert not {"load_roles", "services"} & set(config["JupyterHub"])
    assert values["hub"]["loadRoles"]["user"]["scopes"] == ["self", "access:services!service=exchange"]
    assert config["JupyterHub"]["authenticator_class"] == "ltiauthenticator.lti13.auth.LTI13Authenticator"
    lti = config["LTI13Authenticator"]
    assert lti["issuer"].startswith("https://") and lti["client_id"]
    # the chart's hub image has this authenticator (images/hub/requirements.txt of 4.4.0)
    assert re.search(r"jupyterhub-ltiauthenticator==1\.6\.", (CHART / "README.md").read_text())


def test_values_give_a_class_our_image_limits_culling_storage_and_the_exchange(values):
    single = values["singleuser"]
    assert single["cmd"] == "start-lab" and single["uid"] == 1000
    assert single["storage"]["homeMountPath"] == "/home/student/work"  # where start-lab copies the lessons
    assert values["prePuller"]["hook"]["enabled"] and values["prePuller"]["continuous"]["enabled"]
    assert values["cull"]["enabled"] and 0 < values["cull"]["timeout"] <= 3600

    need("jupyterhub")
    from jupyterhub.traitlets import ByteSpecification  # how KubeSpawner reads them (M = 2**20)

    mib = lambda q: ByteSpecification().validate(None, q) / 2**20  # noqa: E731
    guarantee, limit = mib(single["memory"]["guarantee"]), mib(single["memory"]["limit"])
    assert guarantee == 256 and limit == 1024
    # at the guarantee, at least 80 students with a kernel each fit on a 24 GB node (2.5 GB kept
    # for the node, as bench/memory.py counts)
    assert (24e9 - 2.5e9) / 2**20 // guarantee >= 80
    exchange = values["hub"]["services"]["exchange"]
    assert exchange["url"].endswith(":10102")
    assert {"name": "exchange", "port": 10102, "targetPort": 10102} in values["hub"]["service"]["extraPorts"]
    # reachable through the network policies: into the hub pod, and out of the students' pods
    assert any({"port": 10102} in rule["ports"] for rule in values["hub"]["networkPolicy"]["ingress"])
    assert any({"port": 10102, "protocol": "TCP"} in rule["ports"] for rule in single["networkPolicy"]["egress"])
    assert single["extraEnv"]["SNAKEKIT_EXCHANGE_URL"] == "http://hub:10102/services/exchange/"


def test_instructors_servers_get_the_course_and_students_do_not(values):
    """hub.extraConfig's pre-spawn hook, run as the hub runs it on KubeSpawner's spawner."""
    from types import SimpleNamespace

    traitlets = need("traitlets.config")
    c = traitlets.Config()
    for name, code in values["hub"]["extraConfig"].items():
        exec(compile(code, f"hub.extraConfig.{name}", "exec"), {"c": c})  # noqa: S102 (our values file)
    hook = c.KubeSpawner.pre_spawn_hook

    def spawner(*groups):
        user = SimpleNamespace(groups=[SimpleNamespace(name=g) for g in groups])
        return SimpleNamespace(user=user, volumes=[{"name": "home"}], volume_mounts=[{"name": "home"}],
                               environment={"SNAKEKIT_EXCHANGE_URL": "x"}, mem_guarantee="256M", mem_limit="1G",
                               image=students_image)

    students_image = f"{values['singleuser']['image']['name']}:{values['singleuser']['image']['tag']}"

    ta, student = spawner("instructors"), spawner("students")
    hook(ta)
    hook(student)
    assert {"name": "course", "mountPath": "/home/student/course"} in ta.volume_mounts
    assert {"name": "course", "persistentVolumeClaim": {"claimName": "snakekit-course"}} in ta.volumes
    assert ta.environment == {"SNAKEKIT_EXCHANGE_URL": "x", "SNAKEKIT_ROLE": "instructor"}
    assert student.volumes == [{"name": "home"}] and student.volume_mounts == [{"name": "home"}]
    assert "SNAKEKIT_ROLE" not in student.environment and student.mem_limit == "1G"
    # the course (solutions, hidden cases) is only in the grader's image, which only they run
    assert student.image == students_image == "registry.example.edu/snakekit-lab:0.1.0"
    assert ta.image == "registry.example.edu/snakekit-grader:0.1.0"
