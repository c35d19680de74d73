//! deploy/ checked against the server it deploys: the mistakes that pass `docker build` and
//! `kubectl apply` and only show up as a pod that never gets ready or a port nobody answers on.
//!
//! - Container ports, EXPOSE, the HEALTHCHECK and the Prometheus annotation use the server's
//!   default addresses ([`crease_server::DEFAULT_HTTP`], [`crease_server::DEFAULT_GRPC`]).
//! - The probes ask /healthz and /readyz on the HTTP container port.
//! - The Services target the container's port names and select the Deployment's pods.
//! - Every file kustomization.yaml names exists, and every manifest is named.
//! - Names resolve: the PVC, the Secret and its key, the HPA's target, the kustomize image.
//! - The image and the Deployment agree: user id, the cache directory, the web folder.
//! - The Dockerfile's dependency layer copies every workspace member, and its toolchain and
//!   runtime base match.
//! - Every `--flag` the image and the Deployment pass exists in `crease-server --help`.
//! - The optional KEDA ScaledObject (`deploy/keda/`) scales the Deployment on the stream and
//!   consumer the replicas create for batch jobs, through NATS's monitoring port.
//!
//! The workspace has no YAML crate, so [`yaml`] below reads the block-style subset the manifests
//! are written in and fails, naming the line, on anything outside it.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use yaml::Node;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("server/ sits in the workspace root")
        .to_path_buf()
}

fn read(rel: &str) -> String {
    let path = repo().join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn k8s(file: &str) -> Vec<Node> {
    let rel = format!("deploy/k8s/{file}");
    yaml::parse(&read(&rel), &rel)
}

/// The single document of `file` whose `kind` is `kind`.
fn resource(file: &str, kind: &str) -> Node {
    let mut found: Vec<Node> = k8s(file)
        .into_iter()
        .filter(|d| d.opt("kind").map(Node::str) == Some(kind))
        .collect();
    assert_eq!(found.len(), 1, "deploy/k8s/{file}: expected one {kind}");
    found.remove(0)
}

fn port_of(addr: &str) -> u16 {
    addr.parse::<SocketAddr>()
        .unwrap_or_else(|e| panic!("{addr}: {e}"))
        .port()
}

/// The value following `flag` in an argument list (`--flag VALUE` or `--flag=VALUE`).
fn flag_value(args: &[String], flag: &str) -> Option<String> {
    let prefix = format!("{flag}=");
    args.iter().enumerate().find_map(|(i, a)| {
        if a == flag {
            args.get(i + 1).cloned()
        } else {
            a.strip_prefix(&prefix).map(str::to_string)
        }
    })
}

fn container() -> Node {
    let deployment = resource("deployment.yaml", "Deployment");
    let containers = deployment.at("spec.template.spec.containers").seq();
    containers
        .iter()
        .find(|c| c.at("name").str() == "crease-server")
        .expect("deployment.yaml: a container named crease-server")
        .clone()
}

/// The container's `command` and `args`, as strings.
fn container_args(c: &Node) -> Vec<String> {
    ["command", "args"]
        .iter()
        .filter_map(|k| c.opt(k))
        .flat_map(|n| n.seq().iter().map(|a| a.str().to_string()))
        .collect()
}

/// The HTTP and gRPC ports the server listens on in the Deployment: its defaults unless the
/// arguments name others.
fn served_ports() -> (u16, u16) {
    let args = container_args(&container());
    let http = flag_value(&args, "--http").unwrap_or_else(|| crease_server::DEFAULT_HTTP.into());
    let grpc = flag_value(&args, "--grpc").unwrap_or_else(|| crease_server::DEFAULT_GRPC.into());
    (port_of(&http), port_of(&grpc))
}

/// Container port numbers by name.
fn container_ports(c: &Node) -> Vec<(String, u16)> {
    c.at("ports")
        .seq()
        .iter()
        .map(|p| {
            let name = p.opt("name").map(Node::str).unwrap_or("").to_string();
            (name, p.at("containerPort").u16())
        })
        .collect()
}

#[test]
fn container_ports_are_the_server_defaults() {
    let (http, grpc) = served_ports();
    let ports = container_ports(&container());
    assert!(
        ports.contains(&("http".into(), http)),
        "deployment.yaml: want port `http` = {http} (crease_server::DEFAULT_HTTP), got {ports:?}"
    );
    assert!(
        ports.contains(&("grpc".into(), grpc)),
        "deployment.yaml: want port `grpc` = {grpc} (crease_server::DEFAULT_GRPC), got {ports:?}"
    );

    let deployment = resource("deployment.yaml", "Deployment");
    let annotations = deployment.at("spec.template.metadata.annotations");
    assert_eq!(
        annotations.at("prometheus.io/port").str(),
        http.to_string(),
        "deployment.yaml: the prometheus.io/port annotation should be the HTTP port"
    );
    assert_eq!(
        annotations.at("prometheus.io/path").str(),
        "/metrics",
        "deployment.yaml: prometheus.io/path"
    );

    let docker = Dockerfile::read();
    let runtime = docker.runtime();
    let exposed: BTreeSet<u16> = runtime
        .iter()
        .filter(|i| i.keyword == "EXPOSE")
        .flat_map(|i| i.args.split_whitespace())
        .map(|p| p.trim_end_matches("/tcp").parse().expect("EXPOSE port"))
        .collect();
    assert!(
        exposed.contains(&http) && exposed.contains(&grpc),
        "Dockerfile: EXPOSE {exposed:?}, want {http} and {grpc}"
    );
    let health = Dockerfile::one(runtime, "HEALTHCHECK");
    assert!(
        health.args.contains(&format!(":{http}/healthz")),
        "Dockerfile: HEALTHCHECK should ask :{http}/healthz: {}",
        health.args
    );
}

#[test]
fn probes_hit_healthz_and_readyz_on_the_http_port() {
    let c = container();
    let (http, _) = served_ports();
    let ports = container_ports(&c);
    let probe = |kind: &str, paths: &[&str]| {
        let get = c.at(&format!("{kind}.httpGet"));
        let path = get.at("path").str();
        assert!(
            paths.contains(&path),
            "{kind}: path {path}, want one of {paths:?}"
        );
        // A port is a name or a number; either way it must be the HTTP listener.
        let port = get.at("port").str();
        let number = match port.parse::<u16>() {
            Ok(n) => n,
            Err(_) => {
                ports
                    .iter()
                    .find(|(name, _)| name == port)
                    .unwrap_or_else(|| panic!("{kind}: port {port} is no container port name"))
                    .1
            }
        };
        assert_eq!(
            number, http,
            "{kind}: probes port {port}, the HTTP listener is {http}"
        );
    };
    probe("livenessProbe", &["/healthz"]);
    probe("readinessProbe", &["/readyz"]);
    probe("startupProbe", &["/healthz", "/readyz"]);
}

#[test]
fn services_target_named_container_ports_and_select_the_pods() {
    let deployment = resource("deployment.yaml", "Deployment");
    let pod_labels = deployment.at("spec.template.metadata.labels").map();
    let subset = |what: &str, labels: &[(String, Node)]| {
        for (k, v) in labels {
            assert!(
                pod_labels.iter().any(|(pk, pv)| pk == k && pv == v),
                "{what}: {k}={} is not a label of the Deployment's pods",
                v.str()
            );
        }
    };
    subset(
        "Deployment spec.selector",
        deployment.at("spec.selector.matchLabels").map(),
    );

    let names: Vec<String> = container_ports(&container())
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    let mut targeted = BTreeSet::new();
    let mut services = 0;
    for file in kustomize_resources() {
        for doc in k8s(&file) {
            // The server's Services (nats.yaml's is checked by its own test).
            if doc.opt("kind").map(Node::str) != Some("Service")
                || doc
                    .opt("spec.selector.app.kubernetes.io/name")
                    .map(Node::str)
                    != Some("crease")
            {
                continue;
            }
            services += 1;
            let what = format!("{file} ({})", doc.at("metadata.name").str());
            subset(&what, doc.at("spec.selector").map());
            for p in doc.at("spec.ports").seq() {
                let target = p.at("targetPort").str();
                assert!(
                    names.iter().any(|n| n == target),
                    "{what}: targetPort {target} should be one of the container's port names {names:?}"
                );
                if target == "grpc" {
                    assert_eq!(p.at("appProtocol").str(), "grpc", "{what}: appProtocol");
                }
                targeted.insert(target.to_string());
            }
        }
    }
    assert!(services > 0, "kustomization.yaml lists no Service");
    for want in ["http", "grpc"] {
        assert!(targeted.contains(want), "no Service targets port `{want}`");
    }
}

/// The files named under `resources:` in kustomization.yaml.
fn kustomize_resources() -> Vec<String> {
    let kustomization = k8s("kustomization.yaml").remove(0);
    kustomization
        .at("resources")
        .seq()
        .iter()
        .map(|r| r.str().to_string())
        .collect()
}

#[test]
fn kustomization_names_existing_files_and_every_manifest() {
    let dir = repo().join("deploy/k8s");
    let listed = kustomize_resources();
    for file in &listed {
        assert!(
            dir.join(file).is_file(),
            "kustomization.yaml names {file}, which does not exist"
        );
    }
    let mut manifests: Vec<String> = std::fs::read_dir(&dir)
        .expect("deploy/k8s")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".yaml") || n.ends_with(".yml"))
        .collect();
    manifests.sort();
    for file in manifests {
        // Examples are placeholders (a dummy admin token): apply them never, and by hand.
        let example = file.contains(".example.");
        let named = listed.contains(&file);
        if file == "kustomization.yaml" {
            continue;
        }
        assert!(
            named != example,
            "deploy/k8s/{file}: {}",
            if example {
                "an example must not be applied by kustomization.yaml"
            } else {
                "not listed in kustomization.yaml, so `kubectl apply -k` skips it"
            }
        );
    }
}

#[test]
fn names_resolve_between_manifests() {
    let deployment = resource("deployment.yaml", "Deployment");
    let name = deployment.at("metadata.name").str();
    let pod = deployment.at("spec.template.spec");
    let c = container();

    // The models: --models points at a read-only mount of the crease-models claim.
    let pvc = resource("pvc.yaml", "PersistentVolumeClaim");
    let claim = pvc.at("metadata.name").str();
    let args = container_args(&c);
    let models = flag_value(&args, "--models").expect("deployment.yaml: --models DIR");
    let mount = c
        .at("volumeMounts")
        .seq()
        .iter()
        .find(|m| m.at("mountPath").str() == models)
        .unwrap_or_else(|| panic!("--models {models}: nothing is mounted there"))
        .clone();
    assert_eq!(
        mount.at("readOnly").str(),
        "true",
        "the models mount is read-only"
    );
    let volume = pod
        .at("volumes")
        .seq()
        .iter()
        .find(|v| v.at("name").str() == mount.at("name").str())
        .expect("the models mount names a volume")
        .clone();
    assert_eq!(
        volume.at("persistentVolumeClaim.claimName").str(),
        claim,
        "deployment.yaml: the models volume should claim pvc.yaml's PersistentVolumeClaim"
    );

    // The admin token: the env var the server reads, from the example Secret's name and key.
    let secret = resource("secret.example.yaml", "Secret");
    let env = c
        .at("env")
        .seq()
        .iter()
        .find(|e| e.at("name").str() == "CREASE_ADMIN_TOKEN")
        .expect("deployment.yaml: env CREASE_ADMIN_TOKEN")
        .clone();
    let key_ref = env.at("valueFrom.secretKeyRef");
    assert_eq!(
        key_ref.at("name").str(),
        secret.at("metadata.name").str(),
        "deployment.yaml: CREASE_ADMIN_TOKEN should come from the Secret in secret.example.yaml"
    );
    let key = key_ref.at("key").str();
    assert!(
        secret.at("stringData").opt(key).is_some(),
        "secret.example.yaml has no key {key}"
    );

    // The autoscaler: scales this Deployment, which leaves the count to it and has a CPU
    // request for utilisation to be measured against.
    let hpa = resource("hpa.yaml", "HorizontalPodAutoscaler");
    assert_eq!(
        hpa.at("spec.scaleTargetRef.kind").str(),
        "Deployment",
        "hpa.yaml: target kind"
    );
    assert_eq!(
        hpa.at("spec.scaleTargetRef.name").str(),
        name,
        "hpa.yaml: should scale the Deployment in deployment.yaml"
    );
    assert!(
        deployment.opt("spec.replicas").is_none(),
        "deployment.yaml: spec.replicas resets the HPA's count on every apply"
    );
    assert!(
        c.opt("resources.requests.cpu").is_some(),
        "deployment.yaml: the HPA needs a CPU request"
    );

    // kustomize's image override matches the image actually used.
    let kustomization = k8s("kustomization.yaml").remove(0);
    let image = c.at("image").str();
    let repository = image.rsplit_once(':').map_or(image, |(r, _)| r);
    for i in kustomization.at("images").seq() {
        assert_eq!(
            i.at("name").str(),
            repository,
            "kustomization.yaml images[].name"
        );
    }
}

#[test]
fn image_and_deployment_agree() {
    let docker = Dockerfile::read();
    let runtime = docker.runtime();
    let deployment = resource("deployment.yaml", "Deployment");
    let c = container();

    // runAsNonRoot can only be checked against a numeric user.
    let user = Dockerfile::one(runtime, "USER").args.clone();
    let uid = user.split(':').next().unwrap_or("");
    assert!(
        uid.parse::<u32>().is_ok_and(|u| u != 0),
        "Dockerfile: USER {user} should be a numeric non-root uid"
    );
    if let Some(run_as) = deployment.opt("spec.template.spec.securityContext.runAsUser") {
        assert_eq!(
            run_as.str(),
            uid,
            "deployment.yaml runAsUser vs the image's USER"
        );
    }

    // The cache must stay writable under a read-only root filesystem.
    let cache = runtime
        .iter()
        .filter(|i| i.keyword == "ENV")
        .find_map(|i| {
            i.args
                .split_whitespace()
                .find_map(|kv| kv.strip_prefix("CREASE_CACHE_DIR="))
        })
        .expect("Dockerfile: ENV CREASE_CACHE_DIR=...")
        .to_string();
    let read_only = c
        .opt("securityContext.readOnlyRootFilesystem")
        .is_some_and(|n| n.str() == "true");
    let overridden = c.opt("env").is_some_and(|env| {
        env.seq()
            .iter()
            .any(|e| e.at("name").str() == "CREASE_CACHE_DIR")
    });
    if read_only && !overridden {
        let mounted = c.at("volumeMounts").seq().iter().any(|m| {
            m.at("mountPath").str() == cache && m.opt("readOnly").is_none_or(|r| r.str() != "true")
        });
        assert!(
            mounted,
            "deployment.yaml: read-only root filesystem but nothing writable at {cache}"
        );
    }

    // The server binary is what runs, and --web points where web/ is copied.
    let entrypoint = Dockerfile::exec_form(Dockerfile::one(runtime, "ENTRYPOINT"));
    assert_eq!(
        entrypoint.first().map(String::as_str),
        Some("crease-server"),
        "Dockerfile: ENTRYPOINT should run crease-server"
    );
    assert!(
        runtime.iter().any(|i| i.keyword == "COPY"
            && i.args.starts_with("--from=")
            && i.args.contains("target/release/crease-server")),
        "Dockerfile: the runtime stage copies target/release/crease-server"
    );
    if let Some(web) = flag_value(&entrypoint, "--web") {
        let copied = runtime.iter().any(|i| {
            let words: Vec<&str> = i.args.split_whitespace().collect();
            i.keyword == "COPY"
                && words
                    .first()
                    .is_some_and(|s| s.trim_end_matches('/') == "web")
                && words.last().is_some_and(|d| d.trim_end_matches('/') == web)
        });
        assert!(
            copied,
            "Dockerfile: --web {web}, but web/ is not copied there"
        );
    }
}

/// `(major, minor)` of a Rust version such as "1.87" or "1.95.0".
fn rust_version(v: &str) -> (u32, u32) {
    let mut parts = v
        .split('.')
        .map(|p| p.parse::<u32>().unwrap_or_else(|_| panic!("{v}")));
    (parts.next().unwrap_or(0), parts.next().unwrap_or(0))
}

#[test]
fn dockerfile_builds_every_member_on_a_matching_toolchain() {
    let docker = Dockerfile::read();
    let builder = docker.stages.first().expect("a builder stage");
    let workspace = read("Cargo.toml");

    let members: Vec<String> = {
        // The line that starts with `members` (not `default-members`).
        let start = workspace
            .find("\nmembers = [")
            .expect("Cargo.toml: members");
        let list = &workspace[start..];
        let list = &list[..list.find(']').expect("members ends")];
        list.split('"')
            .skip(1)
            .step_by(2)
            .map(str::to_string)
            .collect()
    };
    assert!(!members.is_empty());
    for m in &members {
        let manifest = format!("{m}/Cargo.toml");
        assert!(
            builder
                .iter()
                .any(|i| i.keyword == "COPY" && i.args.split_whitespace().any(|w| w == manifest)),
            "Dockerfile: the dependency layer does not copy {manifest}"
        );
        assert!(
            builder.iter().any(
                |i| i.keyword == "COPY" && i.args.split_whitespace().next() == Some(m.as_str())
            ),
            "Dockerfile: the sources of {m} are not copied"
        );
        let stand_ins = builder
            .iter()
            .find(|i| i.keyword == "RUN" && i.args.contains("members="))
            .expect("Dockerfile: the stand-in RUN with members=");
        assert!(
            stand_ins.args.split(['"', ' ']).any(|w| w == m),
            "Dockerfile: the stand-in sources skip member {m}"
        );
    }

    // The builder's toolchain is at least the workspace's rust-version, and the binary it links
    // against glibc runs on the runtime image: same Debian release.
    let from = |stage: &[Instruction]| docker.expand(&Dockerfile::one(stage, "FROM").args);
    let build_image = from(builder);
    let runtime_image = from(docker.runtime());
    let tag = build_image
        .split_whitespace()
        .next()
        .and_then(|i| i.strip_prefix("rust:"))
        .unwrap_or_else(|| panic!("builder FROM {build_image}: want rust:<version>-<debian>"));
    let (version, debian) = tag.split_once('-').expect("rust:<version>-<debian>");
    let wanted = workspace
        .lines()
        .find_map(|l| l.trim().strip_prefix("rust-version = "))
        .expect("Cargo.toml: rust-version")
        .trim_matches('"');
    assert!(
        rust_version(version) >= rust_version(wanted),
        "Dockerfile builds with rust {version}, the workspace needs {wanted}"
    );
    assert!(
        runtime_image.contains(debian),
        "builder is Debian {debian}, runtime is {runtime_image}: glibc may not match"
    );
}

/// Copies `from` (a file or a folder, recursively) to `to`.
fn copy_path(from: &Path, to: &Path) {
    fn must<T>(r: std::io::Result<T>, path: &Path) -> T {
        r.unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    }
    if from.is_dir() {
        must(std::fs::create_dir_all(to), to);
        for e in must(std::fs::read_dir(from), from) {
            let e = must(e, from);
            copy_path(&e.path(), &to.join(e.file_name()));
        }
    } else {
        let parent = to.parent().expect("a file has a parent");
        must(std::fs::create_dir_all(parent), parent);
        must(std::fs::copy(from, to), from);
    }
}

/// The builder stage's dependency layer, outside Docker: its COPY lines (the manifests, the
/// lockfile, proto's build script and protos) into a folder standing for WORKDIR, then its
/// stand-in RUN there with the dependency build swapped for `cargo fetch --locked`
/// for this host, which loads every manifest and its targets as the build would (`cargo
/// metadata` does not look for target files): a `[[bench]]`, `[[test]]` or `[[example]]` the
/// stand-ins miss, a member the RUN forgets, a lockfile out of date, all fail here as they would
/// in `docker build`. (The real-source half of the stage is the workspace build every test run
/// does.)
#[test]
fn the_builder_stages_stand_ins_are_manifests_cargo_accepts() {
    let docker = Dockerfile::read();
    let builder = docker.stages.first().expect("a builder stage");
    let dir = tempfile::tempdir().unwrap();
    let build = "cargo build --release --locked -p crease-demo -p crease-cli";
    let mut ran = false;
    for i in builder {
        match i.keyword.as_str() {
            "COPY" if !ran => {
                let words: Vec<&str> = i.args.split_whitespace().collect();
                let (dest, sources) = words.split_last().expect("COPY src... dest");
                for src in sources {
                    let from = repo().join(src);
                    let to = if dest.ends_with('/') {
                        dir.path()
                            .join(dest)
                            .join(from.file_name().expect("a named source"))
                    } else {
                        dir.path().join(dest)
                    };
                    copy_path(&from, &to);
                }
            }
            "RUN" if !ran && i.args.contains("members=") => {
                assert!(
                    i.args.contains(build),
                    "Dockerfile: the stand-in RUN should `{build}`"
                );
                let script = i.args.replace(
                    build,
                    "cargo fetch --locked --target \"$(rustc -vV | sed -n 's/^host: //p')\"",
                );
                let out = std::process::Command::new("bash")
                    .args(["-o", "pipefail", "-c", &script])
                    .current_dir(dir.path())
                    .output()
                    .unwrap();
                assert!(
                    out.status.success(),
                    "the stand-in RUN outside Docker: {}\n{}",
                    out.status,
                    String::from_utf8_lossy(&out.stderr)
                );
                ran = true;
            }
            _ => {}
        }
    }
    assert!(
        ran,
        "Dockerfile: no stand-in RUN (members=...) in the builder stage"
    );
    // The RUN removed its stand-ins again: the real sources come next.
    for m in ["core", "proto", "demo", "client"] {
        assert!(
            !dir.path().join(m).join("src").exists(),
            "{m}/src left behind"
        );
    }
}

/// The paths under `/node_modules/` that web/index.html's import map names.
fn import_map_modules() -> Vec<String> {
    let html = read("web/index.html");
    let mut modules: Vec<String> = html
        .split("\"/node_modules/")
        .skip(1)
        .map(|rest| rest[..rest.find('"').expect("a closing quote")].to_owned())
        .collect();
    // The modules import some packages by a relative path (a worker sees no import map).
    let mut scripts: Vec<_> = std::fs::read_dir(repo().join("web"))
        .expect("web/ is readable")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "js"))
        .collect();
    scripts.sort();
    for script in scripts {
        let text = std::fs::read_to_string(&script)
            .unwrap_or_else(|e| panic!("{}: {e}", script.display()));
        for line in text
            .lines()
            .filter(|l| l.trim_start().starts_with("import "))
        {
            if let Some(rest) = line.split("\"./node_modules/").nth(1) {
                let module = rest[..rest.find('"').expect("a closing quote")].to_owned();
                if !modules.contains(&module) {
                    modules.push(module);
                }
            }
        }
    }
    modules
}

/// The image installs the viewer's packages from web/'s lockfile (`npm ci`), the runtime
/// stage copies them beside web/, a local `node_modules` stays out of the build context, and
/// the stage's RUN, run here outside Docker on the files it copies, gives every module the
/// import map names and every module the viewer's scripts import from `./node_modules/`.
#[test]
fn the_image_installs_the_viewers_packages_from_the_lockfile() {
    let docker = Dockerfile::read();
    let web = docker
        .stages
        .iter()
        .find(|s| {
            s.iter()
                .any(|i| i.keyword == "COPY" && i.args.contains("web/package-lock.json"))
        })
        .expect("Dockerfile: no stage copies web/package-lock.json (the viewer's packages)");
    let from = &Dockerfile::one(web, "FROM").args;
    let words: Vec<&str> = from.split_whitespace().collect();
    let name = match words.as_slice() {
        [_, as_, name] if as_.eq_ignore_ascii_case("as") => *name,
        _ => panic!("Dockerfile: the packages' stage FROM {from}: want `FROM image AS name`"),
    };
    let workdir = Dockerfile::one(web, "WORKDIR").args.clone();
    let runs: Vec<&Instruction> = web.iter().filter(|i| i.keyword == "RUN").collect();
    assert!(
        runs.iter().any(|r| r.args.contains("npm ci")),
        "Dockerfile: stage {name} should `npm ci` (the lockfile's versions)"
    );
    assert!(
        !runs.iter().any(|r| r.args.contains("npm install")),
        "Dockerfile: stage {name} runs `npm install`, which may move off the lockfile"
    );

    // The runtime stage copies them where --web serves /node_modules from.
    let runtime = docker.runtime();
    let entrypoint = Dockerfile::exec_form(Dockerfile::one(runtime, "ENTRYPOINT"));
    let served = flag_value(&entrypoint, "--web").expect("ENTRYPOINT --web");
    let wanted = format!(
        "--from={name} {}/node_modules {}/node_modules",
        workdir.trim_end_matches('/'),
        served.trim_end_matches('/')
    );
    assert!(
        runtime.iter().any(|i| i.keyword == "COPY"
            && i.args.split_whitespace().collect::<Vec<_>>().join(" ") == wanted),
        "Dockerfile: the runtime stage should COPY {wanted}"
    );
    // A developer's web/node_modules would otherwise ride along in `COPY web/`.
    assert!(
        read(".dockerignore")
            .lines()
            .any(|l| l.trim() == "**/node_modules/" || l.trim() == "**/node_modules"),
        ".dockerignore: **/node_modules/ (a bare node_modules/ matches only the root one)"
    );

    // The stage, outside Docker: its COPY sources into a folder standing for WORKDIR, then its
    // RUN lines there.
    if std::process::Command::new("npm")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("skipped running stage {name}: no npm on PATH (Debian: apt-get install npm)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for copy in web.iter().filter(|i| i.keyword == "COPY") {
        let words: Vec<&str> = copy.args.split_whitespace().collect();
        let (dest, sources) = words.split_last().expect("COPY src... dest");
        assert!(
            *dest == "./" || *dest == ".",
            "Dockerfile: stage {name} copies to {dest}; this test copies into WORKDIR only"
        );
        for src in sources {
            let from = repo().join(src);
            std::fs::copy(&from, dir.path().join(from.file_name().unwrap()))
                .unwrap_or_else(|e| panic!("{}: {e}", from.display()));
        }
    }
    for run in &runs {
        let out = std::process::Command::new("bash")
            .args(["-o", "pipefail", "-c", &run.args])
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "RUN {} in stage {name}: {}\n{}",
            run.args,
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let modules = import_map_modules();
    assert!(
        modules.len() >= 3,
        "web/index.html's import map: {modules:?}"
    );
    for m in &modules {
        let path = dir.path().join("node_modules").join(m);
        assert!(
            if m.ends_with('/') {
                path.is_dir()
            } else {
                path.is_file()
            },
            "the viewer imports /node_modules/{m}, which stage {name} does not install"
        );
    }
    // The locked versions, as web/package.json pins them.
    let package: serde_json::Value = serde_json::from_str(&read("web/package.json")).unwrap();
    for (dep, version) in package["dependencies"].as_object().unwrap() {
        let installed: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(
                dir.path()
                    .join("node_modules")
                    .join(dep)
                    .join("package.json"),
            )
            .unwrap(),
        )
        .unwrap();
        assert_eq!(&installed["version"], version, "{dep}");
    }
}

/// The `--long` flags in `crease-server --help`.
fn help_flags() -> BTreeSet<String> {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_crease-server"))
        .arg("--help")
        .output()
        .expect("run crease-server --help");
    assert!(out.status.success(), "crease-server --help failed");
    long_flags(&String::from_utf8_lossy(&out.stdout))
}

fn long_flags(text: &str) -> BTreeSet<String> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
        .filter(|w| w.len() > 2 && w.starts_with("--"))
        .map(str::to_string)
        .collect()
}

#[test]
fn the_nats_url_names_the_nats_service_and_its_jetstream_statefulset() {
    let args = container_args(&container());
    let url = flag_value(&args, "--nats").expect("deployment.yaml: --nats URL (issue 17)");
    let rest = url
        .strip_prefix("nats://")
        .unwrap_or_else(|| panic!("--nats {url}: expected nats://HOST:PORT"));
    let (host, port) = rest
        .rsplit_once(':')
        .unwrap_or_else(|| panic!("--nats {url}: expected nats://HOST:PORT"));
    let port: u16 = port
        .parse()
        .unwrap_or_else(|_| panic!("--nats {url}: port"));
    assert!(
        kustomize_resources().iter().any(|f| f == "nats.yaml"),
        "kustomization.yaml does not list nats.yaml"
    );
    let service = resource("nats.yaml", "Service");
    assert_eq!(
        service.at("metadata.name").str(),
        host,
        "--nats host vs the Service"
    );
    let client = service
        .at("spec.ports")
        .seq()
        .iter()
        .find(|p| p.at("port").u16() == port)
        .unwrap_or_else(|| panic!("nats.yaml: the Service has no port {port} (--nats {url})"));
    let set = resource("nats.yaml", "StatefulSet");
    assert_eq!(
        set.at("spec.serviceName").str(),
        host,
        "StatefulSet serviceName"
    );
    let pod_labels = set.at("spec.template.metadata.labels").map();
    for (k, v) in service.at("spec.selector").map() {
        assert!(
            pod_labels.iter().any(|(pk, pv)| pk == k && pv == v),
            "nats.yaml: the Service selects {k}={}, not a label of the StatefulSet's pods",
            v.str()
        );
    }
    let nats = &set.at("spec.template.spec.containers").seq()[0];
    let target = client.at("targetPort").str();
    assert!(
        nats.at("ports")
            .seq()
            .iter()
            .any(|p| p.at("name").str() == target && p.at("containerPort").u16() == port),
        "nats.yaml: targetPort {target} is not the container's port {port}"
    );
    let nats_args: Vec<&str> = nats.at("args").seq().iter().map(Node::str).collect();
    // JetStream and its store: on the command line (`-js -sd DIR`) or in the configuration
    // file (`-c FILE`, from the nats-config Secret: issue 40).
    let conf = nats_conf();
    let store: &str = if let Some(i) = nats_args.iter().position(|a| *a == "-c") {
        assert_eq!(
            nats_args.get(i + 1).copied(),
            Some("/etc/nats/nats.conf"),
            "nats.yaml: -c names the mounted nats-config Secret's file"
        );
        conf_value(&conf, "store_dir").expect("nats.conf: jetstream { store_dir: DIR }")
    } else {
        assert!(
            nats_args.contains(&"-js"),
            "nats.yaml: JetStream off (args {nats_args:?})"
        );
        nats_args
            .iter()
            .position(|a| *a == "-sd")
            .and_then(|i| nats_args.get(i + 1))
            .expect("nats.yaml: -sd DIR (the JetStream store)")
    };
    let mounted = nats
        .at("volumeMounts")
        .seq()
        .iter()
        .find(|m| m.at("mountPath").str() == store)
        .unwrap_or_else(|| panic!("nats.yaml: the store {store} is not a mounted volume"));
    let claim = mounted.at("name").str();
    assert!(
        set.at("spec.volumeClaimTemplates")
            .seq()
            .iter()
            .any(|t| t.at("metadata.name").str() == claim),
        "nats.yaml: the store's volume {claim} is not a volumeClaimTemplate"
    );
    // Each replica's id is its pod's name.
    let env = container().at("env").seq().to_vec();
    let id = env
        .iter()
        .find(|e| e.at("name").str() == "CREASE_REPLICA_ID")
        .expect("deployment.yaml: CREASE_REPLICA_ID");
    assert_eq!(id.at("valueFrom.fieldRef.fieldPath").str(), "metadata.name");
}

/// The NATS configuration shipped in cluster-secrets.example.yaml (the `nats.conf` block
/// scalar of the nats-config Secret, read as text: the YAML reader here refuses block scalars).
fn nats_conf() -> String {
    let text = read("deploy/k8s/cluster-secrets.example.yaml");
    text.lines()
        .skip_while(|l| l.trim() != "nats.conf: |")
        .skip(1)
        .take_while(|l| l.starts_with("    ") || l.trim().is_empty())
        .map(|l| format!("{}\n", l.get(4..).unwrap_or("")))
        .collect()
}

/// The value of `key:` in the NATS configuration (the first occurrence).
fn conf_value<'a>(conf: &'a str, key: &str) -> Option<&'a str> {
    let at = conf.find(&format!("{key}:"))? + key.len() + 1;
    conf[at..]
        .split(|c: char| c.is_whitespace() || c == '}' || c == ',')
        .find(|w| !w.is_empty())
}

/// The keys of Secret `name` in cluster-secrets.example.yaml (its `stringData` keys).
fn example_secret_keys(name: &str) -> Vec<String> {
    let text = read("deploy/k8s/cluster-secrets.example.yaml");
    let doc = text
        .split("\n---\n")
        .find(|d| d.lines().any(|l| l.trim() == format!("name: {name}")))
        .unwrap_or_else(|| panic!("cluster-secrets.example.yaml: no Secret {name}"));
    doc.lines()
        .skip_while(|l| l.trim() != "stringData:")
        .skip(1)
        .filter(|l| l.starts_with("  ") && !l.starts_with("    "))
        .filter_map(|l| l.trim().split_once(':').map(|(k, _)| k.to_owned()))
        .collect()
}

/// The Secret and key a file path of `pod` (a pod template's spec) comes from: the mount
/// above it (read-only), its volume's Secret, the file's name as the key.
fn secret_file(pod: &Node, container: &Node, path: &str, what: &str) -> (String, String) {
    let mount = container
        .at("volumeMounts")
        .seq()
        .iter()
        .find(|m| path.starts_with(&format!("{}/", m.at("mountPath").str())))
        .unwrap_or_else(|| panic!("{what} {path}: under no volumeMount"))
        .clone();
    let key = &path[mount.at("mountPath").str().len() + 1..];
    let volume = pod
        .at("volumes")
        .seq()
        .iter()
        .find(|v| v.at("name").str() == mount.at("name").str())
        .unwrap_or_else(|| panic!("{what}: no volume {}", mount.at("name").str()))
        .clone();
    let secret = volume
        .opt("secret")
        .unwrap_or_else(|| {
            panic!(
                "{what} {path}: volume {} is not a Secret",
                mount.at("name").str()
            )
        })
        .at("secretName")
        .str()
        .to_owned();
    (secret, key.to_owned())
}

#[test]
fn the_cluster_trusts_only_its_own_every_credential_comes_from_a_secret() {
    // The replicas: a password, mutual TLS and the cluster key, each a file of a mounted
    // Secret that cluster-secrets.example.yaml defines, with the key the file is named after.
    let deployment = resource("deployment.yaml", "Deployment");
    let pod = deployment.at("spec.template.spec");
    let c = container();
    let args = container_args(&c);
    let help = help_flags();
    for flag in [
        "--nats-password-file",
        "--nats-tls-ca",
        "--nats-tls-cert",
        "--nats-tls-key",
        "--cluster-key-file",
    ] {
        let path =
            flag_value(&args, flag).unwrap_or_else(|| panic!("deployment.yaml: {flag} (issue 40)"));
        assert!(help.contains(flag), "{flag} is not in crease-server --help");
        let (secret, key) = secret_file(pod, &c, &path, flag);
        assert!(
            example_secret_keys(&secret).contains(&key),
            "{flag} {path}: cluster-secrets.example.yaml's Secret {secret} has no key {key}"
        );
        let mount = c
            .at("volumeMounts")
            .seq()
            .iter()
            .find(|m| path.starts_with(m.at("mountPath").str()))
            .unwrap()
            .clone();
        assert_eq!(
            mount.opt("readOnly").map(Node::str),
            Some("true"),
            "{flag}: mounted read-only"
        );
    }
    // Its NATS user is the shipped configuration's replica user, which may publish the
    // cluster's subjects; the observer may publish nothing.
    let conf = nats_conf();
    let user = flag_value(&args, "--nats-user").expect("deployment.yaml: --nats-user");
    let block = &conf[conf
        .find(&format!("user: {user}"))
        .unwrap_or_else(|| panic!("nats.conf: no user {user}"))..];
    let permissions = &block[..block.find("\n        }").unwrap_or(block.len())];
    assert!(
        permissions.contains("publish: [\"crease.>\""),
        "{permissions}"
    );
    assert!(
        conf.contains("publish: { deny: \">\" }"),
        "nats.conf: the observer may publish"
    );
    assert!(
        conf.contains("verify: true"),
        "nats.conf: client certificates not required"
    );

    // NATS: its configuration file and its TLS files from the Secrets the example defines.
    let set = resource("nats.yaml", "StatefulSet");
    let nats_pod = set.at("spec.template.spec");
    let nats = &nats_pod.at("containers").seq()[0];
    let (secret, key) = secret_file(nats_pod, nats, "/etc/nats/nats.conf", "nats.yaml -c");
    assert_eq!(
        (secret.as_str(), key.as_str()),
        ("nats-config", "nats.conf")
    );
    assert!(example_secret_keys("nats-config").contains(&"nats.conf".to_owned()));
    for file in ["cert_file", "key_file", "ca_file"] {
        let path = conf_value(&conf, file).unwrap_or_else(|| panic!("nats.conf: tls {{ {file} }}"));
        let (secret, key) = secret_file(nats_pod, nats, path, file);
        assert!(
            example_secret_keys(&secret).contains(&key),
            "nats.conf {file} {path}: Secret {secret} has no key {key}"
        );
    }
    // And deploy/README.md documents them.
    let readme = read("deploy/README.md");
    for word in [
        "--nats-user",
        "--nats-password-file",
        "--nats-tls-cert",
        "--cluster-key-file",
        "crease.>",
        "cluster-secrets.example.yaml",
    ] {
        assert!(
            readme.contains(word),
            "deploy/README.md does not mention {word}"
        );
    }
}

#[test]
fn every_flag_passed_exists_in_help() {
    let docker = Dockerfile::read();
    let runtime = docker.runtime();
    let mut passed: Vec<(String, &str)> = Vec::new();
    for keyword in ["ENTRYPOINT", "CMD"] {
        for i in runtime.iter().filter(|i| i.keyword == keyword) {
            for a in Dockerfile::exec_form(i) {
                passed.push((a, "Dockerfile"));
            }
        }
    }
    for a in container_args(&container()) {
        passed.push((a, "deployment.yaml"));
    }
    let help = help_flags();
    let missing: Vec<String> = passed
        .iter()
        .filter(|(a, _)| a.starts_with("--"))
        .map(|(a, from)| (a.split('=').next().unwrap_or(a), from))
        .filter(|(flag, _)| !help.contains(*flag))
        .map(|(flag, from)| format!("{flag} ({from})"))
        .collect();
    assert!(
        missing.is_empty(),
        "not in crease-server --help: {missing:?}; --help has {help:?}"
    );
}

// ----- Dockerfile -----------------------------------------------------------------------------

/// One instruction, continuation lines joined.
#[derive(Clone, Debug)]
struct Instruction {
    keyword: String,
    args: String,
}

#[derive(Debug)]
struct Dockerfile {
    /// `ARG` defaults given before the first `FROM` (usable in `FROM`).
    args: Vec<(String, String)>,
    /// Instructions per stage, each starting with its `FROM`.
    stages: Vec<Vec<Instruction>>,
}

impl Dockerfile {
    fn read() -> Self {
        Self::parse(&read("deploy/Dockerfile"))
    }

    fn parse(text: &str) -> Self {
        let mut instructions = Vec::new();
        let mut current = String::new();
        for line in text.lines() {
            let trimmed = line.trim();
            // Comment lines are dropped, also inside a continued instruction.
            if trimmed.starts_with('#') || (trimmed.is_empty() && current.is_empty()) {
                continue;
            }
            match trimmed.strip_suffix('\\') {
                Some(part) => {
                    current.push_str(part);
                    current.push(' ');
                }
                None => {
                    current.push_str(trimmed);
                    let (keyword, args) = current.split_once(' ').unwrap_or((&current, ""));
                    instructions.push(Instruction {
                        keyword: keyword.to_ascii_uppercase(),
                        args: args.trim().to_string(),
                    });
                    current.clear();
                }
            }
        }
        let mut args = Vec::new();
        let mut stages: Vec<Vec<Instruction>> = Vec::new();
        for i in instructions {
            if i.keyword == "FROM" {
                stages.push(Vec::new());
            }
            match stages.last_mut() {
                Some(stage) => stage.push(i),
                None if i.keyword == "ARG" => {
                    let (k, v) = i.args.split_once('=').unwrap_or((&i.args, ""));
                    args.push((k.to_string(), v.trim_matches('"').to_string()));
                }
                None => panic!("Dockerfile: {} before the first FROM", i.keyword),
            }
        }
        assert!(
            stages.len() >= 2,
            "Dockerfile: want a builder and a runtime stage"
        );
        Self { args, stages }
    }

    /// The final stage: what the image runs.
    fn runtime(&self) -> &[Instruction] {
        self.stages.last().expect("stages")
    }

    /// The only `keyword` instruction of a stage.
    fn one<'a>(stage: &'a [Instruction], keyword: &str) -> &'a Instruction {
        let mut found = stage.iter().filter(|i| i.keyword == keyword);
        let one = found
            .next()
            .unwrap_or_else(|| panic!("Dockerfile: no {keyword}"));
        assert!(
            found.next().is_none(),
            "Dockerfile: more than one {keyword} in a stage"
        );
        one
    }

    /// `["a", "b"]`: the arguments. Shell form is refused: it would run under `sh -c` and not
    /// receive the stop signal.
    fn exec_form(i: &Instruction) -> Vec<String> {
        assert!(
            i.args.starts_with('['),
            "Dockerfile: {} {}: use the exec form [\"...\"]",
            i.keyword,
            i.args
        );
        yaml::scalar(&i.args, "Dockerfile", 0)
            .seq()
            .iter()
            .map(|n| n.str().to_string())
            .collect()
    }

    /// `${NAME}` replaced by the global `ARG` defaults.
    fn expand(&self, text: &str) -> String {
        self.args.iter().fold(text.to_string(), |t, (k, v)| {
            t.replace(&format!("${{{k}}}"), v)
                .replace(&format!("${k}"), v)
        })
    }
}

#[test]
fn the_keda_scaler_reads_the_job_queue_the_replicas_create() {
    let rel = "deploy/keda/scaledobject.yaml";
    let docs = yaml::parse(&read(rel), rel);
    assert_eq!(docs.len(), 1, "{rel}: one ScaledObject");
    let scaled = &docs[0];
    assert_eq!(scaled.at("kind").str(), "ScaledObject");
    let deployment = resource("deployment.yaml", "Deployment");
    assert_eq!(
        scaled.at("spec.scaleTargetRef.name").str(),
        deployment.at("metadata.name").str(),
        "{rel}: scaleTargetRef names the Deployment"
    );
    let triggers = scaled.at("spec.triggers").seq();
    let jetstream = triggers
        .iter()
        .find(|t| t.at("type").str() == "nats-jetstream")
        .unwrap_or_else(|| panic!("{rel}: no nats-jetstream trigger"));
    let meta = jetstream.at("metadata");
    assert_eq!(
        meta.at("stream").str(),
        crease_server::cluster::work::JOBS_STREAM
    );
    assert_eq!(
        meta.at("consumer").str(),
        crease_server::cluster::work::JOBS_CONSUMER
    );
    // The monitoring endpoint: the NATS Service's `monitor` port, in the kustomization's
    // namespace.
    let service = resource("nats.yaml", "Service");
    let monitor = service
        .at("spec.ports")
        .seq()
        .iter()
        .find(|p| p.at("name").str() == "monitor")
        .expect("nats.yaml: a Service port named monitor")
        .at("port")
        .u16();
    let namespace = k8s("kustomization.yaml")
        .remove(0)
        .at("namespace")
        .str()
        .to_owned();
    assert_eq!(
        meta.at("natsServerMonitoringEndpoint").str(),
        format!(
            "{}.{namespace}.svc.cluster.local:{monitor}",
            service.at("metadata.name").str()
        )
    );
    assert!(
        triggers.iter().any(|t| t.at("type").str() == "cpu"),
        "{rel}: the CPU trigger keeps the HPA's rule for live rooms"
    );
}

// ----- YAML subset ----------------------------------------------------------------------------

/// Block mappings and sequences, plain and quoted scalars, flow sequences of scalars, `{}`,
/// comments and `---` documents: what Kubernetes manifests are usually written in. Anything else
/// (block scalars, anchors, tags, flow mappings) panics with the file and line, so a manifest
/// edited past this subset fails the test rather than being misread.
mod yaml {
    /// A parsed value. Scalars stay strings (`8080`, `true`): comparisons are textual.
    #[derive(Clone, Debug, PartialEq)]
    pub(crate) enum Node {
        Scalar(String),
        Seq(Vec<Node>),
        Map(Vec<(String, Node)>),
    }

    impl Node {
        /// The value at a dotted path of mapping keys (keys containing dots, like
        /// `prometheus.io/port`, are tried whole first).
        pub(crate) fn opt(&self, path: &str) -> Option<&Node> {
            if let Node::Map(entries) = self {
                if let Some((_, v)) = entries.iter().find(|(k, _)| k == path) {
                    return Some(v);
                }
                let mut split = path.char_indices().filter(|&(_, c)| c == '.');
                return split.find_map(|(at, _)| {
                    let (head, rest) = (&path[..at], &path[at + 1..]);
                    entries
                        .iter()
                        .find(|(k, _)| k == head)
                        .and_then(|(_, v)| v.opt(rest))
                });
            }
            None
        }

        /// Like [`Node::opt`], panicking with the path when absent.
        pub(crate) fn at(&self, path: &str) -> &Node {
            self.opt(path).unwrap_or_else(|| panic!("missing `{path}`"))
        }

        pub(crate) fn str(&self) -> &str {
            match self {
                Node::Scalar(s) => s,
                other => panic!("expected a scalar, got {other:?}"),
            }
        }

        pub(crate) fn u16(&self) -> u16 {
            self.str()
                .parse()
                .unwrap_or_else(|_| panic!("expected a port number, got {}", self.str()))
        }

        pub(crate) fn seq(&self) -> &[Node] {
            match self {
                Node::Seq(items) => items,
                other => panic!("expected a sequence, got {other:?}"),
            }
        }

        pub(crate) fn map(&self) -> &[(String, Node)] {
            match self {
                Node::Map(entries) => entries,
                other => panic!("expected a mapping, got {other:?}"),
            }
        }
    }

    struct Line {
        no: usize,
        indent: usize,
        text: String,
    }

    /// Every document of `src`; `file` names it in errors.
    pub(crate) fn parse(src: &str, file: &str) -> Vec<Node> {
        let mut docs = Vec::new();
        let mut lines = Vec::new();
        for (i, raw) in src.lines().enumerate() {
            let no = i + 1;
            if raw.trim_end() == "---" {
                docs.push(document(std::mem::take(&mut lines), file));
                continue;
            }
            assert!(!raw.contains('\t'), "{file}:{no}: tab in YAML");
            let text = strip_comment(raw);
            if text.trim().is_empty() {
                continue;
            }
            let indent = text.len() - text.trim_start().len();
            lines.push(Line {
                no,
                indent,
                text: text.trim().to_string(),
            });
        }
        docs.push(document(lines, file));
        docs.into_iter().flatten().collect()
    }

    fn document(mut lines: Vec<Line>, file: &str) -> Option<Node> {
        let first = lines.first()?.indent;
        let mut i = 0;
        let node = block(&mut lines, &mut i, first, file);
        if let Some(l) = lines.get(i) {
            panic!("{file}:{}: unexpected indentation", l.no);
        }
        Some(node)
    }

    /// `line` without a trailing `# comment` (a `#` at the start or after a space, outside
    /// quotes).
    fn strip_comment(line: &str) -> &str {
        let mut quote = None;
        let mut prev = ' ';
        for (at, c) in line.char_indices() {
            match quote {
                Some(q) if c == q => quote = None,
                Some(_) => {}
                None if c == '"' || c == '\'' => quote = Some(c),
                None if c == '#' && prev.is_whitespace() => return &line[..at],
                None => {}
            }
            prev = c;
        }
        line
    }

    fn is_dash(text: &str) -> bool {
        text == "-" || text.starts_with("- ")
    }

    /// `key: value` split at the first `: ` (or final `:`) outside quotes.
    fn entry(text: &str) -> Option<(String, &str)> {
        let mut quote = None;
        for (at, c) in text.char_indices() {
            match quote {
                Some(q) if c == q => quote = None,
                Some(_) => {}
                None if c == '"' || c == '\'' => quote = Some(c),
                None if c == '{' || c == '[' => return None,
                None if c == ':' => {
                    let rest = &text[at + 1..];
                    if rest.is_empty() || rest.starts_with(' ') {
                        let key = text[..at].trim().trim_matches(['"', '\'']).to_string();
                        return Some((key, rest.trim()));
                    }
                }
                None => {}
            }
        }
        None
    }

    fn block(lines: &mut [Line], i: &mut usize, indent: usize, file: &str) -> Node {
        if is_dash(&lines[*i].text) {
            sequence(lines, i, indent, file)
        } else {
            mapping(lines, i, indent, file)
        }
    }

    fn sequence(lines: &mut [Line], i: &mut usize, indent: usize, file: &str) -> Node {
        let mut items = Vec::new();
        while *i < lines.len() && lines[*i].indent == indent && is_dash(&lines[*i].text) {
            let (no, text) = (lines[*i].no, lines[*i].text.clone());
            let rest = text[1..].trim_start();
            if rest.is_empty() {
                *i += 1;
                match lines.get(*i) {
                    Some(next) if next.indent > indent => {
                        let inner = next.indent;
                        items.push(block(lines, i, inner, file));
                    }
                    _ => items.push(Node::Scalar(String::new())),
                }
            } else if is_dash(rest) {
                panic!("{file}:{no}: nested `- -` sequences are outside the subset");
            } else if entry(rest).is_some() {
                // `- key: value`: the item is a mapping whose first line starts after the dash.
                let inner = indent + (text.len() - rest.len());
                lines[*i].indent = inner;
                lines[*i].text = rest.to_string();
                items.push(mapping(lines, i, inner, file));
            } else {
                items.push(scalar(rest, file, no));
                *i += 1;
            }
        }
        Node::Seq(items)
    }

    fn mapping(lines: &mut [Line], i: &mut usize, indent: usize, file: &str) -> Node {
        let mut entries: Vec<(String, Node)> = Vec::new();
        while *i < lines.len() && lines[*i].indent == indent && !is_dash(&lines[*i].text) {
            let no = lines[*i].no;
            let text = lines[*i].text.clone();
            let (key, value) =
                entry(&text).unwrap_or_else(|| panic!("{file}:{no}: expected `key: value`"));
            *i += 1;
            let node = if !value.is_empty() {
                scalar(value, file, no)
            } else {
                match lines.get(*i) {
                    Some(next) if next.indent > indent => {
                        let inner = next.indent;
                        block(lines, i, inner, file)
                    }
                    // A sequence may sit at its key's indentation.
                    Some(next) if next.indent == indent && is_dash(&next.text) => {
                        sequence(lines, i, indent, file)
                    }
                    _ => Node::Scalar(String::new()),
                }
            };
            assert!(
                entries.iter().all(|(k, _)| *k != key),
                "{file}:{no}: duplicate key {key}"
            );
            entries.push((key, node));
        }
        if let Some(l) = lines.get(*i).filter(|l| l.indent > indent) {
            panic!("{file}:{}: unexpected indentation", l.no);
        }
        Node::Map(entries)
    }

    /// A scalar, or a flow sequence of scalars, or `{}`.
    pub(crate) fn scalar(text: &str, file: &str, no: usize) -> Node {
        let text = text.trim();
        if let Some(inner) = text.strip_prefix('[') {
            let inner = inner
                .strip_suffix(']')
                .unwrap_or_else(|| panic!("{file}:{no}: unclosed ["));
            return Node::Seq(
                split_flow(inner)
                    .into_iter()
                    .filter(|s| !s.trim().is_empty())
                    .map(|s| scalar(s, file, no))
                    .collect(),
            );
        }
        if text == "{}" {
            return Node::Map(Vec::new());
        }
        if let Some(inner) = text.strip_prefix('"') {
            let inner = inner
                .strip_suffix('"')
                .unwrap_or_else(|| panic!("{file}:{no}: unclosed \""));
            return Node::Scalar(inner.replace("\\\"", "\"").replace("\\\\", "\\"));
        }
        if let Some(inner) = text.strip_prefix('\'') {
            let inner = inner
                .strip_suffix('\'')
                .unwrap_or_else(|| panic!("{file}:{no}: unclosed '"));
            return Node::Scalar(inner.replace("''", "'"));
        }
        if text.starts_with(['{', '|', '>', '&', '*', '!']) {
            panic!("{file}:{no}: `{text}` is outside the YAML subset this test reads");
        }
        Node::Scalar(text.to_string())
    }

    /// `a, "b, c", d` split at commas outside quotes.
    fn split_flow(text: &str) -> Vec<&str> {
        let mut parts = Vec::new();
        let (mut quote, mut start) = (None, 0);
        for (at, c) in text.char_indices() {
            match quote {
                Some(q) if c == q => quote = None,
                Some(_) => {}
                None if c == '"' || c == '\'' => quote = Some(c),
                None if c == ',' => {
                    parts.push(&text[start..at]);
                    start = at + 1;
                }
                None => {}
            }
        }
        parts.push(&text[start..]);
        parts
    }

    #[test]
    fn reads_the_subset_and_refuses_the_rest() {
        let doc = &parse(
            "a: 1 # note\nb:\n  - x\n  - name: y\n    port: \"80\"\nc:\n- [\"--m\", '/v']\nd: {}\n---\ne: f\n",
            "t",
        );
        assert_eq!(doc.len(), 2);
        assert_eq!(doc[0].at("a").str(), "1");
        assert_eq!(doc[0].at("b").seq()[0].str(), "x");
        assert_eq!(doc[0].at("b").seq()[1].at("port").str(), "80");
        assert_eq!(doc[0].at("c").seq()[0].seq()[1].str(), "/v");
        assert_eq!(doc[0].at("d"), &Node::Map(Vec::new()));
        assert_eq!(doc[1].at("e").str(), "f");
        let refused = std::panic::catch_unwind(|| parse("a: |\n  text\n", "t"));
        assert!(refused.is_err(), "block scalars are refused");
        let misindented = std::panic::catch_unwind(|| parse("a:\n    b: 1\n  c: 2\n", "t"));
        assert!(misindented.is_err(), "inconsistent indentation is refused");
    }
}
