#!/usr/bin/env python3
"""Runs every poseforest command line of deploy/ through the real argument parser.

  check_deploy_commands.py --bin build/bin/poseforest [--deploy DIR] [--source ROOT]
                           [--kubectl PROGRAM] [--rendered-json FILE]

Extracts the command lines a deployment would run:
  - deploy/docker/Dockerfile.*: ENTRYPOINT + CMD (exec form) with the image's ENV;
  - deploy/k8s: what `kubectl kustomize deploy/k8s` renders (what `kubectl apply -k` applies;
    every object of a deploy/k8s/*.yaml but *.example.yaml must be in it), each container of a
    Deployment/StatefulSet/DaemonSet/Job/Pod: its command/args (or the image's ENTRYPOINT/CMD;
    images are matched to Dockerfiles through the `docker build -f deploy/docker/Dockerfile.X -t
    IMAGE` line in each Dockerfile), the image's ENV overlaid with the container's env (fieldRef
    metadata.name -> "<name>-0"), $(VAR) expanded; and the command of each exec probe (a
    poseforest probe must give the container's DDS transport and job flags, with the same
    values), each httpGet probe's port must be one of the container's.
and runs `poseforest <command> ARGS --check-config` (parses the flags, loads the job, the Fast DDS
XML profile and the security files, exits 0 without joining DDS) inside a fake file-system root:
absolute paths in arguments and environment values are moved under a temporary folder that holds
what the container would see: files the Dockerfile COPYs from the repository, its VOLUMEs,
ConfigMap data at their mountPaths, emptyDirs, Secrets filled with test DDS credentials from
deploy/security/make-test-ca.sh (a Secret volume with `items`: a test value in each item's path,
with the item's mode or the volume's defaultMode), PersistentVolumeClaims (which must be rendered too)
as empty folders, and for an image run without Kubernetes, the ConfigMap's job at
/etc/poseforest/job.textproto (the documented mount). A command of another program (the
discovery server, `sh` of a probe) is checked to exist on PATH and listed.
  - deploy/compose.yaml: each service as `docker compose config` renders it (the file's
    ${VAR:-default} with this environment, YAML anchors and merges): its entrypoint/command (or
    the image's), the image's ENV plus `environment`, bind mounts (the host file, which must
    exist) and named volumes; each service's image must be built by its `build.dockerfile`, a
    Dockerfile of deploy/docker; every network `internal` and no published port or host network
    (the cluster's traffic stays on its own bridge); Prometheus's `--config.file` through
    `promtool check config` (when promtool is installed). When a compose CLI is installed
    (`docker compose` v2, or Debian's docker-compose 1.29) its `config` must accept the file
    and render the same command lines; without one, that comparison is skipped and said so.
A Kubernetes command runs in a mount and network namespace of its own (`unshare`) whose
/etc/hosts maps the manifests' Service names (NAME, NAME.NS, NAME.NS.svc,
NAME.NS.svc.cluster.local) to test addresses, as the cluster's DNS would: a host name in a flag
or an XML profile must name a Service of the manifests, and no lookup leaves the machine. A
compose service's command likewise, with the compose services' names in its /etc/hosts.

Exit 0 when every command passes; 1 naming each file, container and the parser's message.
--rendered-json FILE: also write the rendered objects there (a JSON list), for the test's checks.
Needs python3-yaml and kubectl (Debian: kubernetes-client; its 1.20 renders these files as a newer
kubectl does). --compose-cli "docker-compose" (or "docker compose", "none") picks the compose CLI.
"""

import argparse
import glob
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile

import yaml

WORKLOAD_KINDS = {"Deployment", "StatefulSet", "DaemonSet", "Job", "Pod", "ReplicaSet"}
PROBES = ("startupProbe", "readinessProbe", "livenessProbe")
# Flags that say where a worker or coordinator meets its job: a probe that runs `poseforest ...
# --check-config` must give the same as the container, or it checks another set-up.
TRANSPORT_FLAGS = ("--domain", "--job", "--profile", "--peers", "--interfaces", "--dds-xml", "--dds-profile",
                   "--discovery-server", "--security")


def transport_flags(argv):
    """{flag: value} of TRANSPORT_FLAGS in a command line ("--flag value" or "--flag=value")."""
    out, i = {}, 0
    while i < len(argv):
        flag, eq, value = argv[i].partition("=")
        if flag in TRANSPORT_FLAGS:
            if not eq:
                i += 1
                value = argv[i] if i < len(argv) else ""
            out[flag] = value
        i += 1
    return out


def render_kustomization(kubectl, k8s_dir):
    """The objects `kubectl kustomize k8s_dir` renders, or (None, error)."""
    if shutil.which(kubectl) is None:
        return None, f"{kubectl} is not on PATH (Debian: kubernetes-client; scripts/setup.sh installs it)"
    try:
        r = subprocess.run([kubectl, "kustomize", k8s_dir], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return None, f"`{kubectl} kustomize {k8s_dir}` did not finish in 120 s"
    if r.returncode != 0:
        return None, f"`{kubectl} kustomize` fails (exit {r.returncode}): {r.stderr.strip()}"
    try:
        return [d for d in yaml.safe_load_all(r.stdout) if d], None
    except yaml.YAMLError as e:
        return None, f"`{kubectl} kustomize` printed no valid YAML: {e}"


def object_key(d):
    m = d.get("metadata", {})
    return (d.get("kind"), m.get("namespace", ""), m.get("name"))


def dockerfile_instructions(path):
    """(instruction, argument text) pairs, continuation lines joined, comments dropped."""
    out, cur = [], ""
    with open(path) as f:
        for raw in f:
            line = raw.rstrip("\n")
            if not cur and (not line.strip() or line.lstrip().startswith("#")):
                continue
            if cur and line.lstrip().startswith("#"):  # comment inside a continued instruction
                continue
            if line.endswith("\\"):
                cur += line[:-1] + " "
                continue
            cur += line
            parts = cur.strip().split(None, 1)
            out.append((parts[0].upper(), parts[1] if len(parts) > 1 else ""))
            cur = ""
    if cur.strip():
        parts = cur.strip().split(None, 1)
        out.append((parts[0].upper(), parts[1] if len(parts) > 1 else ""))
    return out


class Image:
    def __init__(self, path):
        self.path = path
        self.name = None
        self.entrypoint, self.cmd, self.env, self.copies, self.volumes = [], [], {}, [], []
        self.errors = []
        with open(path) as f:
            m = re.search(r"docker build -f deploy/docker/(\S+) -t (\S+)", f.read())
        if m:
            if m.group(1) != os.path.basename(path):
                self.errors.append(f"its docker build line names {m.group(1)}")
            self.name = m.group(2).split(":")[0]
        stage = 0
        for ins, arg in dockerfile_instructions(path):
            if ins == "FROM":
                stage += 1
                self.entrypoint, self.cmd, self.env, self.copies, self.volumes = [], [], {}, [], []
            elif ins in ("ENTRYPOINT", "CMD"):
                try:
                    value = json.loads(arg)
                except json.JSONDecodeError:
                    self.errors.append(f"{ins} {arg}: use the exec form [\"prog\", \"arg\", ...]")
                    continue
                if ins == "ENTRYPOINT":
                    self.entrypoint, self.cmd = value, []  # Docker: a new ENTRYPOINT resets CMD
                else:
                    self.cmd = value
            elif ins == "ENV":
                tokens = shlex.split(arg)
                if tokens and "=" not in tokens[0]:  # legacy "ENV KEY value"
                    self.env[tokens[0]] = " ".join(tokens[1:])
                else:
                    for t in tokens:
                        k, _, v = t.partition("=")
                        self.env[k] = re.sub(r"\$\{?(\w+)\}?", lambda mm: self.env.get(mm.group(1), ""), v)
            elif ins == "COPY":
                tokens = shlex.split(arg)
                if any(t.startswith("--from") for t in tokens):
                    continue  # build outputs: the binaries
                tokens = [t for t in tokens if not t.startswith("--")]
                for src in tokens[:-1]:
                    self.copies.append((src, tokens[-1]))
            elif ins == "VOLUME":
                try:
                    self.volumes += json.loads(arg)
                except json.JSONDecodeError:
                    self.volumes += arg.split()


def fake_path(root, value):
    """An absolute path moved under root; "--flag=/path" too; anything else unchanged."""
    if value.startswith("/"):
        return root + value
    m = re.match(r"^(--[\w-]+=)(/.*)$", value)
    if m:
        return m.group(1) + root + m.group(2)
    return value


def place_image_files(image, root, source):
    for src, dst in image.copies:
        s = os.path.join(source, src)
        d = root + dst
        if dst.endswith("/") or os.path.isdir(s):
            d = os.path.join(d, os.path.basename(src))
        os.makedirs(os.path.dirname(d), exist_ok=True)
        if os.path.isdir(s):
            shutil.copytree(s, d, dirs_exist_ok=True)
        elif os.path.exists(s):
            shutil.copy(s, d)
        else:
            raise RuntimeError(f"COPY {src}: no such file in {source}")
    for v in image.volumes:
        os.makedirs(root + v, exist_ok=True)


def cluster_hosts(docs):
    """/etc/hosts text mapping every Service of the manifests to an address (its clusterIP when
    the manifest fixes one, else a test address in 10.96.255.0/24), under the names a pod of the
    same namespace resolves it by."""
    lines = ["127.0.0.1 localhost"]
    n = 0
    for _, d in docs:
        if d.get("kind") != "Service":
            continue
        name, ns = d["metadata"]["name"], d["metadata"].get("namespace", "default")
        ip = d.get("spec", {}).get("clusterIP")
        if not ip or ip == "None":
            n += 1
            ip = f"10.96.255.{n}"
        lines.append(f"{ip} {name} {name}.{ns} {name}.{ns}.svc {name}.{ns}.svc.cluster.local")
    return "\n".join(lines) + "\n"


def run_check(binary, argv, env, root, label, source, hosts_file=None):
    """argv: the container's command line (argv[0] a program name). Returns an error or None.
    hosts_file: run in namespaces of its own (unshare) with this file as /etc/hosts."""
    if not argv:
        return f"{label}: no command (no command/args and no image ENTRYPOINT)"
    prog = os.path.basename(argv[0])
    if prog != "poseforest":
        if shutil.which(prog) is None:
            return f"{label}: {prog} is not on PATH here (Debian: fastdds-tools for fast-discovery-server)"
        print(f"ok   {label}: {' '.join(argv)}  (not a poseforest command: {prog} exists)")
        return None
    args = [fake_path(root, a) for a in argv[1:]]
    full_env = {k: fake_path(root, v) for k, v in env.items() if k != "PATH"}
    full_env["PATH"] = os.environ.get("PATH", "/usr/bin:/bin")
    for k in ("POSEFOREST_DATA_DIR", "HOME"):
        if k in os.environ:
            full_env.setdefault(k, os.environ[k])
    command = [binary] + args + ([] if "--check-config" in args else ["--check-config"])
    if hosts_file:  # -r: a user namespace too when not root (mounting needs it)
        command = ["unshare"] + (["-r"] if os.geteuid() != 0 else []) + \
            ["-m", "-n", "sh", "-c", 'mount --bind "$0" /etc/hosts && exec "$@"', hosts_file] + command
    r = subprocess.run(command, env=full_env, cwd=root, capture_output=True, text=True, timeout=60)
    text = (r.stdout + r.stderr).strip().replace(root, "")
    shown = " ".join(argv)
    if r.returncode != 0:
        return f"{label}: `{shown}` (env {json.dumps(env)}) fails the parser (exit {r.returncode}):\n    " + \
            text.replace("\n", "\n    ")
    print(f"ok   {label}: {shown}\n     -> {text.splitlines()[-1] if text else ''}")
    return None


def tls_test_pair(tmp):
    """A self-signed test certificate and key (PEM texts) for a kubernetes.io/tls Secret's tls.crt/tls.key."""
    d = os.path.join(tmp, "http-tls")
    if not os.path.isdir(d):
        os.makedirs(d)
        subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
                        "-days", "2", "-keyout", os.path.join(d, "tls.key"), "-out", os.path.join(d, "tls.crt"),
                        "-subj", "/CN=localhost"], check=True, capture_output=True)
    return {k: open(os.path.join(d, k)).read() for k in ("tls.crt", "tls.key")}


def make_credentials(dest, source, tmp):
    """A test CA's credentials for one participant, all six files flat in dest (a Secret mount)."""
    ca = os.path.join(tmp, "ca")
    if not os.path.isdir(ca):
        subprocess.run(["sh", os.path.join(source, "deploy/security/make-test-ca.sh"), ca, "participant"], check=True,
                       capture_output=True)
    os.makedirs(dest, exist_ok=True)
    for f in ("identity_ca.pem", "permissions_ca.pem", "governance.p7s"):
        shutil.copy(os.path.join(ca, f), dest)
    for f in ("cert.pem", "key.pem", "permissions.p7s"):
        shutil.copy(os.path.join(ca, "participant", f), dest)


def interpolate(value, env):
    """Compose's variable substitution in a string: $$, $VAR, ${VAR}, ${VAR:-default},
    ${VAR-default}, ${VAR:?message}, ${VAR?message}. Returns (text, errors)."""
    errors = []

    def one(m):
        if m.group(0) == "$$":
            return "$"
        name = m.group("braced") or m.group("plain")
        op, arg = m.group("op") or "", m.group("arg") or ""
        have = name in env
        val = env.get(name, "")
        if op == ":-":
            return val if val else arg
        if op == "-":
            return val if have else arg
        if op in (":?", "?") and (not have or (op == ":?" and not val)):
            errors.append(f"${{{name}}} is not set: {arg}")
        if not have and not op:
            errors.append(f"${name} is not set and has no default (${{{name}:-default}})")
        return val

    pattern = r"\$\$|\$\{(?P<braced>\w+)(?:(?P<op>:-|-|:\?|\?)(?P<arg>[^}]*))?\}|\$(?P<plain>[A-Za-z_]\w*)"
    return re.sub(pattern, one, value), errors


def interpolate_tree(node, env, errors):
    if isinstance(node, str):
        text, errs = interpolate(node, env)
        errors += errs
        return text
    if isinstance(node, list):
        return [interpolate_tree(x, env, errors) for x in node]
    if isinstance(node, dict):
        return {k: interpolate_tree(v, env, errors) for k, v in node.items() if not str(k).startswith("x-")}
    return node


def compose_cli(choice):
    """The compose CLI as an argv prefix: `docker compose` (v2) when it answers, else
    docker-compose (Debian's 1.29); None when neither is installed or choice is "none"."""
    if choice == "none":
        return None
    candidates = [choice.split()] if choice else [["docker", "compose"], ["docker-compose"]]
    for c in candidates:
        if shutil.which(c[0]) is None:
            continue
        try:
            r = subprocess.run(c + ["version"], capture_output=True, text=True, timeout=30)
        except subprocess.TimeoutExpired:
            continue
        if r.returncode == 0:
            return c
    return None


def short_image(name):
    return str(name or "").split("/")[-1].split(":")[0]


def compose_checks(compose_file, deploy, source, images, cli_choice):
    """deploy/compose.yaml: (services {name: rendered service}, errors, notes)."""
    label = os.path.relpath(compose_file, os.path.dirname(deploy))
    errors, notes = [], []
    try:
        with open(compose_file) as f:
            raw = yaml.safe_load(f)
    except yaml.YAMLError as e:
        return {}, [f"{label}: not valid YAML: {e}"], notes
    if not isinstance(raw, dict) or not isinstance(raw.get("services"), dict):
        return {}, [f"{label}: no services"], notes
    ierrors = []
    doc = interpolate_tree(raw, dict(os.environ), ierrors)
    errors += [f"{label}: {e}" for e in ierrors]
    services = doc["services"]
    base = os.path.dirname(os.path.abspath(compose_file))

    # What the compose CLI makes of it: it must accept the file and run the same command lines.
    cli = compose_cli(cli_choice)
    if cli is None:
        notes.append(f"note {label}: no compose CLI here (`docker compose` v2 or Debian's docker-compose): "
                     f"checked with this script's own rendering only")
    else:
        try:
            r = subprocess.run(cli + ["-f", compose_file, "config"], capture_output=True, text=True, timeout=120,
                               cwd=base)
        except subprocess.TimeoutExpired:
            r = None
            errors.append(f"{label}: `{' '.join(cli)} config` did not finish in 120 s")
        if r is not None and r.returncode != 0:
            errors.append(f"{label}: `{' '.join(cli)} config` refuses it (exit {r.returncode}): "
                          f"{(r.stderr or r.stdout).strip()}")
        elif r is not None:
            rendered = (yaml.safe_load(r.stdout) or {}).get("services", {})
            if sorted(rendered) != sorted(services):
                errors.append(f"{label}: `{' '.join(cli)} config` renders services {sorted(rendered)}, "
                              f"this script {sorted(services)}")
            for name, svc in services.items():
                for key in ("entrypoint", "command"):
                    want = svc.get(key)
                    if isinstance(want, str):
                        want = shlex.split(want)
                    have = rendered.get(name, {}).get(key)
                    if isinstance(have, str):
                        have = shlex.split(have)
                    if want != have:
                        errors.append(f"{label} service {name}: `{' '.join(cli)} config` renders {key} "
                                      f"{json.dumps(have)}, this script {json.dumps(want)}")
            print(f"ok   {label}: `{' '.join(cli)} config` accepts it: services {', '.join(rendered)}")

    # The cluster's traffic stays on its own bridge: internal networks, nothing published.
    networks = doc.get("networks") or {}
    for name, net in networks.items():
        net = net or {}
        if not net.get("internal"):
            errors.append(f"{label}: network {name} is not `internal: true` (the cluster's traffic stays on "
                          f"its bridge, with no route out)")
        if net.get("external") or net.get("driver", "bridge") != "bridge":
            errors.append(f"{label}: network {name}: a bridge network of this file only")
    volumes = doc.get("volumes") or {}
    for name, svc in services.items():
        slabel = f"{label} service {name}"
        if svc.get("network_mode"):
            errors.append(f"{slabel}: network_mode {svc['network_mode']}: use the file's internal network")
        if svc.get("ports"):
            errors.append(f"{slabel}: ports {svc['ports']}: nothing is published (the host reaches the "
                          f"containers on the bridge)")
        nets = svc.get("networks") or []
        for n in (nets if isinstance(nets, list) else list(nets)):
            if n not in networks:
                errors.append(f"{slabel}: network {n} is not defined in the file")
        if not nets:
            errors.append(f"{slabel}: no network: it would join compose's default network, which is not internal")
        # Image and build: the image is the one its Dockerfile's `docker build ... -t` line names.
        img = images.get(short_image(svc.get("image")))
        build = svc.get("build")
        if build is not None:
            if isinstance(build, str):
                build = {"context": build}
            context = os.path.normpath(os.path.join(base, build.get("context", ".")))
            dockerfile = os.path.join(context, build.get("dockerfile", "Dockerfile"))
            if not os.path.isfile(dockerfile):
                errors.append(f"{slabel}: build.dockerfile {build.get('dockerfile')} is not a file in the context "
                              f"{os.path.relpath(context, base)}")
            else:
                built = Image(dockerfile)
                if built.name != short_image(svc.get("image")):
                    errors.append(f"{slabel}: image {svc.get('image')} but its build.dockerfile "
                                  f"{build.get('dockerfile')} is built as {built.name}")
                img = built  # built from this context: its COPY sources are the context's files
                svc["_context"] = context
        if img is None:
            errors.append(f"{slabel}: image {svc.get('image')} has no Dockerfile in deploy/docker "
                          f"(known: {', '.join(sorted(images))})")
            continue
        svc["_image"] = img
        svc["_label"] = slabel
        mounts = []
        for v in svc.get("volumes") or []:
            if isinstance(v, str):
                parts = v.split(":")
                src, dst = (parts[0], parts[1]) if len(parts) > 1 else (None, parts[0])
            else:
                src, dst = v.get("source"), v.get("target")
            if src and (src.startswith((".", "/", "~"))):
                host = os.path.normpath(os.path.join(base, os.path.expanduser(src)))
                if not os.path.exists(host):
                    errors.append(f"{slabel}: bind mount {src}: {host} does not exist")
                    continue
                mounts.append(("bind", host, dst))
            else:
                if src and src not in volumes:
                    errors.append(f"{slabel}: volume {src} is not defined in the file")
                mounts.append(("volume", src, dst))
        svc["_mounts"] = mounts
    return services, errors, notes


def http_port(service):
    """The port of a poseforest service's `--http HOST:PORT` (or --http=...), or None."""
    argv = [str(x) for x in (service.get("command") or [])]
    for i, x in enumerate(argv):
        value = argv[i + 1] if x == "--http" and i + 1 < len(argv) else x[7:] if x.startswith("--http=") else None
        if value and ":" in value:
            return value.rsplit(":", 1)[1]
    return None


def scrape_target_errors(config_file, services):
    """Each scrape target of a Prometheus config (static targets HOST:PORT, dns_sd names with
    their port) must be a compose service that serves HTTP on that port (`--http ...:PORT`)."""
    with open(config_file) as f:
        config = yaml.safe_load(f) or {}
    errors, targets = [], []
    for job in config.get("scrape_configs") or []:
        for sc in job.get("static_configs") or []:
            for t in sc.get("targets") or []:
                host, _, port = str(t).rpartition(":")
                targets.append((job.get("job_name"), host, port))
        for sd in job.get("dns_sd_configs") or []:
            for n in sd.get("names") or []:
                targets.append((job.get("job_name"), n, str(sd.get("port", ""))))
    for job, host, port in targets:
        if host not in services:
            errors.append(f"job {job}: target {host}:{port} is no service of the compose file")
        elif http_port(services[host]) != port:
            errors.append(f"job {job}: target {host}:{port}, but service {host} serves --http on port "
                          f"{http_port(services[host])}")
    return errors


def compose_hosts(services, subnet):
    """/etc/hosts text giving every compose service name an address of the network, as
    compose's network DNS does."""
    prefix = ".".join((subnet or "10.250.0.0/24").split("/")[0].split(".")[:3])
    lines = ["127.0.0.1 localhost"]
    for i, name in enumerate(sorted(services)):
        lines.append(f"{prefix}.{10 + i} {name}")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", required=True, help="the built poseforest program")
    here = os.path.dirname(os.path.abspath(__file__))
    ap.add_argument("--source", default=os.path.normpath(os.path.join(here, "..", "..")))
    ap.add_argument("--deploy", default=None, help="deploy folder (default SOURCE/deploy)")
    ap.add_argument("--kubectl", default="kubectl", help="kubectl program (default: kubectl on PATH)")
    ap.add_argument("--rendered-json", default=None, help="write what kubectl kustomize renders here (JSON)")
    ap.add_argument("--compose-cli", default="",
                    help='compose CLI for `config` ("docker compose", "docker-compose"; "none": skip; default: '
                         'whichever is installed)')
    a = ap.parse_args()
    binary = os.path.abspath(a.bin)
    deploy = os.path.abspath(a.deploy or os.path.join(a.source, "deploy"))
    errors, checked = [], 0

    images = {}
    dockerfiles = sorted(p for p in glob.glob(os.path.join(deploy, "docker", "Dockerfile.*"))
                         if not p.endswith(".dockerignore"))
    for p in dockerfiles:
        img = Image(p)
        label = os.path.relpath(p, os.path.dirname(deploy))
        errors += [f"{label}: {e}" for e in img.errors]
        if img.name is None:
            errors.append(f"{label}: no `docker build -f deploy/docker/{os.path.basename(p)} -t IMAGE` line")
        else:
            images[img.name] = img

    # The files, for naming where each rendered object comes from.
    sources = {}
    for p in sorted(glob.glob(os.path.join(deploy, "k8s", "*.yaml"))):
        try:
            with open(p) as f:
                for d in yaml.safe_load_all(f):
                    if d and d.get("kind") != "Kustomization":
                        sources[object_key(d)] = p
        except yaml.YAMLError as e:
            errors.append(f"{os.path.relpath(p, os.path.dirname(deploy))}: not valid YAML: {e}")
    # What `kubectl apply -k deploy/k8s` applies.
    k8s_dir = os.path.join(deploy, "k8s")
    rendered, error = render_kustomization(a.kubectl, k8s_dir)
    docs = []
    if error:
        errors.append(f"deploy/k8s: {error}")
    else:
        print(f"ok   deploy/k8s: `kubectl kustomize` renders {len(rendered)} objects: " +
              ", ".join(f"{d.get('kind')}/{d.get('metadata', {}).get('name')}" for d in rendered))
        docs = [(sources.get(object_key(d), os.path.join(k8s_dir, "kustomization.yaml")), d) for d in rendered]
        keys = {object_key(d) for d in rendered}
        for key, p in sources.items():
            if key not in keys and not p.endswith(".example.yaml"):
                errors.append(f"{os.path.relpath(p, os.path.dirname(deploy))}: {key[0]}/{key[2]} is not in what "
                              f"`kubectl kustomize deploy/k8s` renders (list the file in kustomization.yaml)")
        if a.rendered_json:
            with open(a.rendered_json, "w") as f:
                json.dump(rendered, f, indent=1)
    claims = {d["metadata"]["name"] for _, d in docs if d.get("kind") == "PersistentVolumeClaim"}
    configmaps = {d["metadata"]["name"]: d.get("data", {}) for _, d in docs if d.get("kind") == "ConfigMap"}
    job_text = next((data["job.textproto"] for data in configmaps.values() if "job.textproto" in data), None)

    with tempfile.TemporaryDirectory(prefix="pf-deploy-check-") as tmp:
        # The images as `docker run IMAGE` starts them (a job mounted at the documented place).
        for name, img in images.items():
            root = tempfile.mkdtemp(dir=tmp)
            label = os.path.relpath(img.path, os.path.dirname(deploy))
            try:
                place_image_files(img, root, a.source)
            except RuntimeError as e:
                errors.append(f"{label}: {e}")
                continue
            if job_text is not None:
                os.makedirs(root + "/etc/poseforest", exist_ok=True)
                with open(root + "/etc/poseforest/job.textproto", "w") as f:
                    f.write(job_text)
            e = run_check(binary, img.entrypoint + img.cmd, img.env, root, label, a.source)
            checked += 1
            if e:
                errors.append(e)

        # Kubernetes workloads, with the cluster's Service names.
        hosts_file = os.path.join(tmp, "hosts")
        with open(hosts_file, "w") as f:
            f.write(cluster_hosts(docs))
        for path, d in docs:
            if d.get("kind") not in WORKLOAD_KINDS:
                continue
            spec = d["spec"] if d["kind"] == "Pod" else d["spec"]["template"]["spec"]
            if d["kind"] == "Job":
                spec = d["spec"]["template"]["spec"]
            volumes = {v["name"]: v for v in spec.get("volumes", [])}
            pod_name = d["metadata"]["name"] + "-0"
            for c in spec.get("initContainers", []) + spec.get("containers", []):
                label = f"{os.path.relpath(path, os.path.dirname(deploy))} {d['kind']}/{d['metadata']['name']} " \
                        f"container {c['name']}"
                image_name = c.get("image", "").split("/")[-1].split(":")[0]
                img = images.get(image_name)
                if img is None and "command" not in c:
                    errors.append(f"{label}: image {c.get('image')} has no Dockerfile in deploy/docker "
                                  f"(known: {', '.join(sorted(images))}) and the container gives no command")
                    continue
                root = tempfile.mkdtemp(dir=tmp)
                if img is not None:
                    try:
                        place_image_files(img, root, a.source)
                    except RuntimeError as e:
                        errors.append(f"{label}: {e}")
                        continue
                for m in c.get("volumeMounts", []):
                    v = volumes.get(m["name"])
                    if v is None:
                        errors.append(f"{label}: volumeMount {m['name']} has no volume")
                        continue
                    mount = root + m["mountPath"]
                    os.makedirs(mount, exist_ok=True)
                    if "configMap" in v:
                        data = configmaps.get(v["configMap"]["name"])
                        if data is None:
                            errors.append(f"{label}: ConfigMap {v['configMap']['name']} is not in deploy/k8s")
                            continue
                        for key, text in data.items():
                            with open(os.path.join(mount, key), "w") as f:
                                f.write(text)
                    elif "secret" in v and "items" in v["secret"]:
                        # A Secret of named keys (the coordinator's HTTP token; tls.crt/tls.key of a
                        # kubernetes.io/tls Secret: a test certificate and key): each item's path
                        # with a test value and the mode Kubernetes gives it (item mode, else
                        # defaultMode, else 0644), so that a mode the program refuses fails here.
                        for item in v["secret"]["items"]:
                            f = os.path.join(mount, item["path"])
                            os.makedirs(os.path.dirname(f), exist_ok=True)
                            with open(f, "w") as out:
                                if item["key"] in ("tls.crt", "tls.key"):
                                    out.write(tls_test_pair(tmp)[item["key"]])
                                else:
                                    out.write("test-token-for-" + item["key"] + "\n")
                            os.chmod(f, item.get("mode", v["secret"].get("defaultMode", 0o644)))
                    elif "secret" in v:
                        make_credentials(mount, a.source, tmp)
                    elif "persistentVolumeClaim" in v and v["persistentVolumeClaim"]["claimName"] not in claims:
                        errors.append(f"{label}: volume {m['name']}: PersistentVolumeClaim "
                                      f"{v['persistentVolumeClaim']['claimName']} is not in deploy/k8s")
                env = dict(img.env) if img else {}
                for e in c.get("env", []):
                    if "value" in e:
                        env[e["name"]] = re.sub(r"\$\((\w+)\)", lambda mm: env.get(mm.group(1), mm.group(0)),
                                                str(e["value"]))
                    elif e.get("valueFrom", {}).get("fieldRef", {}).get("fieldPath") == "metadata.name":
                        env[e["name"]] = pod_name
                    else:
                        env[e["name"]] = "value-from-" + e["name"]

                def expand(s):
                    return re.sub(r"\$\((\w+)\)", lambda mm: env.get(mm.group(1), mm.group(0)), str(s))

                if "command" in c:
                    argv = [expand(x) for x in c["command"]] + [expand(x) for x in c.get("args", [])]
                else:
                    argv = list(img.entrypoint) + ([expand(x) for x in c["args"]] if "args" in c else list(img.cmd))
                err = run_check(binary, argv, env, root, label, a.source, hosts_file)
                checked += 1
                if err:
                    errors.append(err)
                # Probes: an exec probe's command runs in the same container (its env, its files).
                ports = {p.get("name") for p in c.get("ports", [])} | \
                        {p.get("containerPort") for p in c.get("ports", [])}
                for probe in PROBES:
                    if probe not in c:
                        continue
                    plabel = f"{label} {probe}"
                    if "httpGet" in c[probe]:
                        port = c[probe]["httpGet"].get("port")
                        if port not in ports:
                            errors.append(f"{plabel}: httpGet port {port} is not a port of the container")
                        else:
                            print(f"ok   {plabel}: httpGet {c[probe]['httpGet'].get('path', '/')} on port {port}")
                        continue
                    if "exec" not in c[probe]:
                        print(f"ok   {plabel}: {', '.join(c[probe])} (not checked)")
                        continue
                    # The kubelet expands $(VAR) in a probe's command only from env entries with a
                    # `value` (not valueFrom, not the image's ENV).
                    static = {e["name"]: str(e["value"]) for e in c.get("env", []) if "value" in e}
                    pcommand = [str(x) for x in c[probe]["exec"].get("command", [])]
                    unexpanded = sorted({v for x in pcommand for v in re.findall(r"\$\((\w+)\)", x)} - set(static))
                    if unexpanded:
                        errors.append(f"{plabel}: $({'), $('.join(unexpanded)}) in the command: in a probe Kubernetes "
                                      f"expands only env entries with a value (valueFrom ones become \"\")")
                        continue
                    pargv = [re.sub(r"\$\((\w+)\)", lambda mm: static[mm.group(1)], x) for x in pcommand]
                    if pargv and os.path.basename(pargv[0]) == "poseforest":
                        want, have = transport_flags(argv), transport_flags(pargv)
                        if want != have:
                            errors.append(f"{plabel}: gives {json.dumps(have)} where the container has "
                                          f"{json.dumps(want)}: it would check another transport")
                    err = run_check(binary, pargv, env, root, plabel, a.source, hosts_file)
                    checked += 1
                    if err:
                        errors.append(err)

        # deploy/compose.yaml: each service as compose runs it, with the services' names as hosts.
        compose_file = os.path.join(deploy, "compose.yaml")
        if os.path.exists(compose_file):
            services, cerrors, notes = compose_checks(compose_file, deploy, a.source, images, a.compose_cli)
            errors += cerrors
            for n in notes:
                print(n)
            subnet = None
            for net in (yaml.safe_load(open(compose_file)) or {}).get("networks", {}).values():
                for c in ((net or {}).get("ipam") or {}).get("config") or []:
                    subnet = interpolate(str(c.get("subnet", "")), dict(os.environ))[0] or subnet
            compose_hosts_file = os.path.join(tmp, "compose-hosts")
            with open(compose_hosts_file, "w") as f:
                f.write(compose_hosts(services, subnet))
            for name, svc in services.items():
                if "_image" not in svc:
                    continue
                img, slabel = svc["_image"], svc["_label"]
                root = tempfile.mkdtemp(dir=tmp)
                try:
                    place_image_files(img, root, svc.get("_context", a.source))
                except RuntimeError as e:
                    errors.append(f"{slabel}: {e}")
                    continue
                for kind, src, dst in svc["_mounts"]:
                    target = root + dst
                    if kind == "bind" and os.path.isfile(src):
                        os.makedirs(os.path.dirname(target), exist_ok=True)
                        shutil.copy(src, target)
                    elif kind == "bind":
                        shutil.copytree(src, target, dirs_exist_ok=True)
                    else:
                        os.makedirs(target, exist_ok=True)
                env = dict(img.env)
                environment = svc.get("environment") or {}
                if isinstance(environment, list):
                    environment = dict(e.partition("=")[::2] for e in environment)
                env.update({k: str(v if v is not None else os.environ.get(k, "")) for k, v in environment.items()})

                def as_list(x):
                    return shlex.split(x) if isinstance(x, str) else [str(y) for y in x]

                entry = as_list(svc["entrypoint"]) if svc.get("entrypoint") is not None else list(img.entrypoint)
                if svc.get("command") is not None:
                    cmd = as_list(svc["command"])
                elif svc.get("entrypoint") is not None:
                    cmd = []  # compose: a new entrypoint drops the image's CMD
                else:
                    cmd = list(img.cmd)
                argv = entry + cmd
                err = run_check(binary, argv, env, root, slabel, a.source, compose_hosts_file)
                checked += 1
                if err:
                    errors.append(err)
                # Prometheus: its config file, as the container sees it, through promtool.
                if argv and os.path.basename(argv[0]) == "prometheus":
                    config = next((x.split("=", 1)[1] for x in argv if x.startswith("--config.file=")),
                                  "/etc/prometheus/prometheus.yml")
                    if shutil.which("promtool") is None:
                        print(f"note {slabel}: promtool not installed (Debian: prometheus): {config} not checked")
                    elif not os.path.isfile(root + config):
                        errors.append(f"{slabel}: --config.file {config}: no such file in the image or its mounts")
                    else:
                        r = subprocess.run(["promtool", "check", "config", root + config], capture_output=True,
                                           text=True, timeout=60)
                        text = (r.stdout + r.stderr).strip().replace(root, "")
                        if r.returncode != 0:
                            errors.append(f"{slabel}: `promtool check config {config}` fails:\n    " +
                                          text.replace("\n", "\n    "))
                        else:
                            print(f"ok   {slabel}: promtool check config {config}")
                        for e in scrape_target_errors(root + config, services):
                            errors.append(f"{slabel}: {config}: {e}")

    if checked == 0:
        errors.append(f"no command lines found under {deploy}")
    for e in errors:
        print("FAIL " + e)
    print(f"{checked} command lines checked, {len(errors)} problems")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
