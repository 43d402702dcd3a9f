"""docker/hub/z2jh-values.yaml: a Zero to JupyterHub configuration the chart and the hub accept.

Helm validates a release's values (the chart's values.yaml with the user's file merged on top)
against the chart's values.schema; here the same merge is checked against a copy of Zero to
JupyterHub 4.4.0's schema (docker/hub/z2jh-4.4.0/, its source and licence in README.md there).
The hub's own settings (hub.config) are checked against the classes they configure: the LTI
authenticator's, JupyterHub's and its Authenticator's traits. The pods come from the chart's own
configuration code and KubeSpawner 7.0.0 (the chart's), with the instructors' hook run on them;
the volumes it mounts are checked against the claims z2jh-volumes.yaml makes.
"""

from __future__ import annotations

import copy
import json
import os
import re
from pathlib import Path

import pytest

from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.system  # the hub's Kubernetes configuration: not in `make test-quick`
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


def chart_config(values: dict):
    """The KubeSpawner config the chart's hub builds from these values, and the hook hub.extraConfig sets.

    Runs the chart's own code (z2jh-4.4.0/jupyterhub_config.py and z2jh.py, unchanged): its
    KubeSpawner section (labels, image, resources, environment, node affinity, storage, volumes)
    on the merged values, as the hub pod does at start, then every hub.extraConfig entry in
    order, as that file ends.
    """
    import importlib.util

    traitlets = need("traitlets.config")
    need("yaml")
    spec = importlib.util.spec_from_file_location("z2jh", CHART / "z2jh.py")
    z2jh = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(z2jh)
    # the hub pod reads the merged values from a mounted Secret; here from this merge
    merged = helm_merge(load_yaml(CHART / "values.yaml"), values)
    z2jh._load_config = lambda: merged

    source = (CHART / "jupyterhub_config.py").read_text()
    helper = re.search(r"^def camelCaseify\(s\):\n(?:    .*\n|\n)*?(?=\S)", source, re.M)
    start, end = "common_labels = c.KubeSpawner.common_labels = {}\n", "c.KubeSpawner.volume_mounts = volume_mounts\n"
    assert helper and start in source and end in source, "the chart's config file changed: update chart_config()"
    section = helper.group(0) + source[source.index(start):source.index(end) + len(end)]
    c = traitlets.Config()
    names = {"c": c, "os": os, "re": re, "get_config": z2jh.get_config,
             "set_config_if_not_none": z2jh.set_config_if_not_none,
             "get_name": lambda name: f"snakekit-{name}"}  # a resource's name (the chart's templates give it)
    exec(compile(section, "z2jh-4.4.0/jupyterhub_config.py", "exec"), names)  # noqa: S102 (the chart's code)
    for name, code in sorted(values["hub"]["extraConfig"].items()):
        exec(compile(code, f"hub.extraConfig.{name}", "exec"), {"c": c})  # noqa: S102 (our values file)
    return c


class Group:
    def __init__(self, name: str):
        self.name = name


class User:
    """What KubeSpawner and the hook read of a hub user."""

    def __init__(self, name: str, *groups: str):
        self.name, self.id, self.url = name, sum(map(ord, name)), f"/user/{name}/"
        self.groups = [Group(g) for g in groups]


def extra_volumes_as_a_list(values: dict) -> dict:
    values = copy.deepcopy(values)
    values["singleuser"]["storage"]["extraVolumes"] = [{"name": "shared-data", "emptyDir": {}}]
    values["singleuser"]["storage"]["extraVolumeMounts"] = [{"name": "shared-data", "mountPath": "/srv/data"}]
    return values


def extra_volumes_as_a_dict(values: dict) -> dict:
    values = copy.deepcopy(values)
    values["singleuser"]["storage"]["extraVolumes"] = {"shared-data": {"name": "shared-data", "emptyDir": {}}}
    values["singleuser"]["storage"]["extraVolumeMounts"] = {
        "shared-data": {"name": "shared-data", "mountPath": "/srv/data"}}
    return values


def spawner_volumes_as_lists(config) -> None:
    """KubeSpawner's other form (its default, and what a config may set): lists, not dicts."""
    config.KubeSpawner.volumes = list(config.KubeSpawner.volumes.values())
    config.KubeSpawner.volume_mounts = list(config.KubeSpawner.volume_mounts.values())


# the chart's own form (dicts, from its home volume and none or either form of extraVolumes),
# and KubeSpawner's list form
FORMS = {
    "chart-dicts": (lambda v: v, None),
    "chart-dicts-from-extraVolumes-list": (extra_volumes_as_a_list, None),
    "chart-dicts-from-extraVolumes-dict": (extra_volumes_as_a_dict, None),
    "spawner-lists": (lambda v: v, spawner_volumes_as_lists),
}


@pytest.mark.parametrize("form", FORMS)
def test_instructors_servers_get_the_course_and_students_do_not(values, form, tmp_path, monkeypatch):
    """The hook on KubeSpawner 7.0.0 (the chart's) as the chart configures it: the pod each would get."""
    import asyncio

    need("kubespawner")
    from kubernetes_asyncio.config import kube_config
    from kubespawner import KubeSpawner

    make_values, reshape = FORMS[form]
    form_values = make_values(values)
    if form_values != values:  # the chart accepts that form
        assert schema_errors(form_values) == []
    config = chart_config(form_values)
    if reshape:
        reshape(config)
    assert isinstance(config.KubeSpawner.volumes, list if reshape else dict)

    # KubeSpawner loads a cluster's address when made (never called here: building a pod needs none)
    kubeconfig = tmp_path / "kubeconfig"
    kubeconfig.write_text(json.dumps({
        "apiVersion": "v1", "kind": "Config", "current-context": "class",
        "clusters": [{"name": "class", "cluster": {"server": "https://127.0.0.1:9"}}],
        "users": [{"name": "hub", "user": {"token": "unused"}}],
        "contexts": [{"name": "class", "context": {"cluster": "class", "user": "hub"}}]}))
    monkeypatch.setattr(kube_config, "KUBE_CONFIG_DEFAULT_LOCATION", str(kubeconfig))
    monkeypatch.delenv("KUBERNETES_SERVICE_HOST", raising=False)

    async def pod(user: User):
        spawner = KubeSpawner(config=config, user=user, _mock=True)
        # the hub runs the pre-spawn hook, then KubeSpawner.start builds the pod from the spawner
        spawner.pre_spawn_hook(spawner)
        # the pod as KubeSpawner sends it to the cluster (the Kubernetes API's JSON)
        return spawner.api.api_client.sanitize_for_serialization(await spawner.get_pod_manifest())

    async def both():
        return await pod(User("ta1@example.edu", "instructors")), await pod(User("alice"))

    ta_pod, student_pod = asyncio.run(both())
    def volumes(pod):
        return {v["name"]: v for v in pod["spec"]["volumes"]}

    def mounts(pod):
        [container] = pod["spec"]["containers"]
        return [{"name": m["name"], "mountPath": m["mountPath"]} for m in container["volumeMounts"]]

    home = "/home/student/work"
    for who, built in (("ta1", ta_pod), ("alice", student_pod)):
        # the chart's home volume stays: once, on the user's own claim
        [home_mount] = [m for m in mounts(built) if m["mountPath"] == home]
        claim = volumes(built)[home_mount["name"]]["persistentVolumeClaim"]["claimName"]
        assert claim == f"claim-{who}" or claim.startswith(f"claim-{who}-"), volumes(built)
        if form.startswith("chart-dicts-from"):
            assert {"name": "shared-data", "mountPath": "/srv/data"} in mounts(built)
    assert {"name": "course", "mountPath": "/home/student/course"} in mounts(ta_pod)
    assert volumes(ta_pod)["course"] == {"name": "course", "persistentVolumeClaim": {"claimName": "snakekit-course"}}
    assert "course" not in volumes(student_pod)
    assert not any(m["name"] == "course" or m["mountPath"].startswith("/home/student/course")
                   for m in mounts(student_pod))
    # the course (solutions, hidden cases) is only in the grader's image, which only they run
    [ta_container], [student_container] = ta_pod["spec"]["containers"], student_pod["spec"]["containers"]
    assert student_container["image"] == "registry.example.edu/snakekit-lab:0.1.0"
    assert ta_container["image"] == "registry.example.edu/snakekit-grader:0.1.0"
    env = lambda container: {e["name"]: e.get("value") for e in container["env"]}  # noqa: E731
    assert env(ta_container)["SNAKEKIT_ROLE"] == "instructor" and "SNAKEKIT_ROLE" not in env(student_container)
    assert env(student_container)["SNAKEKIT_VIEWER_HOST"] == "127.0.0.1"
    assert ta_container["resources"]["limits"]["memory"] == 2 * 2**30  # "2G" in KubeSpawner's units
    assert student_container["resources"]["limits"]["memory"] == 2**30
    # nodes nobody labelled still take every pod: node-purpose=user is preferred, never required
    for built in (ta_pod, student_pod):
        affinity = built["spec"]["affinity"]["nodeAffinity"]
        assert "requiredDuringSchedulingIgnoredDuringExecution" not in affinity, affinity
        [preferred] = affinity["preferredDuringSchedulingIgnoredDuringExecution"]
        assert preferred["preference"]["matchExpressions"] == [
            {"key": "hub.jupyter.org/node-purpose", "operator": "In", "values": ["user"]}]


def test_pods_start_on_a_cluster_whose_nodes_nobody_labelled(values):
    """The chart's node-purpose labels are a preference: on unlabelled nodes pods still schedule."""
    for pods in ("corePods", "userPods"):
        assert values["scheduling"][pods]["nodeAffinity"]["matchNodePurpose"] == "prefer", pods
    # and the steps say how to label nodes, for a cluster that keeps students off the hub's node
    readme = kubernetes_section()
    for purpose in ("core", "user"):
        assert f"kubectl label node NODE hub.jupyter.org/node-purpose={purpose}" in readme


def kubernetes_section() -> str:
    readme = (HUB / "README.md").read_text()
    start = readme.index("## A class of 100 to 500 on Kubernetes")
    end = readme.find("\n## ", start + 1)
    return readme[start:end if end > 0 else None]


def test_the_course_volume_is_read_write_many_and_the_exchange_read_write_once(values):
    """The claims the values file mounts are made by z2jh-volumes.yaml, with the access each needs."""
    yaml = need("yaml")
    claims = {doc["metadata"]["name"]: doc for doc in yaml.safe_load_all((HUB / "z2jh-volumes.yaml").read_text())}
    assert all(claim["kind"] == "PersistentVolumeClaim" for claim in claims.values())
    # the exchange: on the hub pod only (hub.extraVolumes); the course: the instructors' hook
    assert {"name": "exchange", "persistentVolumeClaim": {"claimName": "snakekit-exchange"}} in values["hub"]["extraVolumes"]
    hook = values["hub"]["extraConfig"]["snakekit-instructors"]
    assert '"persistentVolumeClaim": {"claimName": "snakekit-course"}' in hook
    assert set(claims) == {"snakekit-exchange", "snakekit-course"}
    assert claims["snakekit-exchange"]["spec"]["accessModes"] == ["ReadWriteOnce"]
    assert claims["snakekit-course"]["spec"]["accessModes"] == ["ReadWriteMany"]
    assert claims["snakekit-course"]["spec"]["storageClassName"]  # a class that offers ReadWriteMany
    # what the steps say, and the command they give, match the manifest
    readme = kubernetes_section()
    assert "`snakekit-course` (ReadWriteMany" in readme and "`snakekit-exchange` (ReadWriteOnce" in readme
    assert "kubectl apply --namespace snakekit -f docker/hub/z2jh-volumes.yaml" in readme
    assert "kubectl apply --namespace snakekit -f docker/hub/z2jh-volumes.yaml" in (HUB / "z2jh-volumes.yaml").read_text()
    assert not re.search(r"no read-write-many storage[^.]* is needed", readme.replace("\n", " "), re.I)
