//! `crease room open|info|close`: manage rooms on a server (opening and closing need the
//! server's admin token). `open` prints the publish token `crease stream --token` takes.

use std::path::PathBuf;

use anyhow::{Context, bail};
use crease_core::runtime::filter::OneEuroParams;
use crease_proto::room::refine_wire;
use crease_proto::v1;

use super::common::{ServerArgs, authorized, get_room, print_refinement, print_skinning};

/// Options of `crease room`.
#[derive(Clone, Debug, clap::Args)]
pub struct RoomArgs {
    /// What to do with the room.
    #[command(subcommand)]
    pub action: RoomAction,
}

/// What to do with a room.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum RoomAction {
    /// Open a room on a model; prints the publish token.
    Open(Box<OpenArgs>),
    /// Show a room's model, settings and counters.
    Info(InfoArgs),
    /// Close a room (its subscribers' streams end).
    Close(CloseArgs),
}

/// The server's admin token.
#[derive(Clone, Debug, clap::Args)]
pub struct AdminArgs {
    /// The server's admin token (`crease-server --admin-token`). Also read from
    /// CREASE_ADMIN_TOKEN.
    #[arg(long, env = "CREASE_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: String,
}

/// Options of `crease room open`.
#[derive(Clone, Debug, clap::Args)]
pub struct OpenArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The admin token that opens and closes rooms.
    #[command(flatten)]
    pub admin: AdminArgs,
    /// Room id: 1-64 characters of A-Z, a-z, 0-9, _ and -.
    #[arg(long)]
    pub room: String,
    /// The model the room runs (`crease-server --models` names models by file stem).
    #[arg(long, required_unless_present = "actors", conflicts_with = "actors")]
    pub model: Option<String>,
    /// A room of several actors (issue 38: both hands of a performer, several performers):
    /// a TOML file of `[[actor]]` tables, each with `name`, `model` and optionally `side`
    /// (left/right), `mirror` (x, y, z or nx,ny,nz: a left hand on a right-hand model),
    /// `performer` and `map` (a marker map, relative to the file; needs --markers-from,
    /// --markers, --webxr or --mediapipe). --beta, --filter, --mocap, --refine and --skinning apply to
    /// every actor. E.g. bench/mocap/art-hands-glove13.toml.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["map", "map_name"])]
    pub actors: Option<PathBuf>,
    /// Translation-solve beta (FKY08 eq. 11): about 3 for keyframing UIs, 0.3 for noisy mocap
    /// (HZY11 Fig. 11). Default: the model's.
    #[arg(long)]
    pub beta: Option<f32>,
    /// Smooth control points with a One Euro filter (for mocap; off for UI rooms). Optional
    /// value: `MIN_CUTOFF_HZ,BETA,D_CUTOFF_HZ` (default 1.5,10,1 for models in metres).
    #[arg(long, value_name = "PARAMS", num_args = 0..=1, default_missing_value = "default")]
    pub filter: Option<String>,
    /// A motion-capture room: beta 0.3 (HZY11 Fig. 11) and the default filter, unless --beta
    /// or --filter say otherwise.
    #[arg(long)]
    pub mocap: bool,
    /// A room that retargets raw capture markers (issue 19) through this marker map (TOML,
    /// bench/mocap/*.toml); publishers then send the capture's markers (`crease stream --tsv`
    /// without --map, `crease bridge`). Needs --markers or --markers-from.
    #[arg(long, value_name = "FILE", conflicts_with = "map_name")]
    pub map: Option<PathBuf>,
    /// The same with a map from the server's maps folder (`crease-server --maps DIR`), by
    /// file stem.
    #[arg(long, value_name = "NAME")]
    pub map_name: Option<String>,
    /// The capture's marker names, in the order its frames carry them (comma-separated).
    #[arg(
        long,
        value_name = "NAMES",
        value_delimiter = ',',
        conflicts_with = "markers_from"
    )]
    pub markers: Option<Vec<String>>,
    /// Take the marker names (and units) from a recording (Qualisys TSV or C3D).
    #[arg(long, value_name = "RECORDING", conflicts_with = "webxr")]
    pub markers_from: Option<PathBuf>,
    /// The capture is WebXR hand tracking (the viewer's "track my hands"): its 75 markers
    /// (every joint's centre, `/dorsal` and `/palmar` points; crease_hand::joint_map) in
    /// metres. With a WebXR joint map, e.g. --map bench/mocap/webxr-back.toml.
    #[arg(long, conflicts_with_all = ["markers", "mediapipe"])]
    pub webxr: bool,
    /// The capture is the viewer's camera (MediaPipe Hands, "track my hands (camera)"): its 21
    /// landmarks per hand (crease_hand::mediapipe_map) in metres. With a MediaPipe map, e.g.
    /// --map bench/mocap/mediapipe-back.toml.
    #[arg(long, conflicts_with_all = ["markers", "markers_from"])]
    pub mediapipe: bool,
    /// Refine every frame's bone rotations against the control points, `ITERATIONS,STRENGTH`
    /// (issue 20; e.g. `4,0.01`), or `off` for the regression alone. Default: the server's
    /// (`crease-server --refine`, 8,0.01 unless set: issue 42). It pays where the performer
    /// leaves the training poses; each iteration costs about one translation solve.
    #[arg(long, value_name = "ITERATIONS,STRENGTH|off", value_parser = crease_proto::room::parse_refine_flag)]
    pub refine: Option<crease_proto::room::RefineFlag>,
    /// How the room skins: `lbs` or `dqs` (issue 22; dual quaternions, Kavan et al. 2007:
    /// no volume loss at twisting joints). Default: the model's (`crease train --skinning`).
    /// A DQS room streams vertices only: it refuses palette subscriptions, which the client
    /// skins with LBS.
    #[arg(long, value_name = "lbs|dqs")]
    pub skinning: Option<crease_core::runtime::skin::Skinning>,
    /// The capture's length unit (with --markers; default "mm").
    #[arg(long, default_value = "mm")]
    pub units: String,
}

/// Beta of `--mocap` rooms (HZY11 Fig. 11: noisy markers, a loose fit).
pub const MOCAP_BETA: f32 = 0.3;

/// Options of `crease room info`.
#[derive(Clone, Debug, clap::Args)]
pub struct InfoArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The room.
    #[arg(long, default_value = "demo")]
    pub room: String,
}

/// Options of `crease room close`.
#[derive(Clone, Debug, clap::Args)]
pub struct CloseArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The admin token that opens and closes rooms.
    #[command(flatten)]
    pub admin: AdminArgs,
    /// The room.
    #[arg(long)]
    pub room: String,
}

/// Parses `--filter`: `default` or three comma-separated numbers.
pub fn parse_filter(spec: &str) -> anyhow::Result<OneEuroParams> {
    if spec == "default" {
        return Ok(OneEuroParams::default());
    }
    let v: Vec<f32> = spec
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| {
            format!("--filter {spec}: expected MIN_CUTOFF_HZ,BETA,D_CUTOFF_HZ, e.g. 1.5,10,1")
        })?;
    let [min_cutoff_hz, beta, d_cutoff_hz] = v[..] else {
        bail!(
            "--filter {spec}: expected 3 numbers (MIN_CUTOFF_HZ,BETA,D_CUTOFF_HZ), got {}",
            v.len()
        );
    };
    let p = OneEuroParams {
        min_cutoff_hz,
        beta,
        d_cutoff_hz,
    };
    if !p.is_valid() {
        bail!("--filter {spec}: cutoffs must be positive and beta non-negative");
    }
    Ok(p)
}

/// Runs `crease room`.
pub fn run(args: &RoomArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(async {
        match &args.action {
            RoomAction::Open(a) => open(a).await,
            RoomAction::Info(a) => info(a).await,
            RoomAction::Close(a) => close(a).await,
        }
    })
}

fn print_filter(filter: Option<&v1::MarkerFilter>) -> String {
    filter.map_or_else(
        || "off".to_owned(),
        |f| {
            format!(
                "One Euro (min cutoff {} Hz, beta {}, speed cutoff {} Hz)",
                f.min_cutoff_hz, f.beta, f.d_cutoff_hz
            )
        },
    )
}

async fn open(args: &OpenArgs) -> anyhow::Result<()> {
    let filter = match args.filter.as_deref() {
        Some(spec) => Some(parse_filter(spec)?),
        None if args.mocap => Some(OneEuroParams::default()),
        None => None,
    };
    let beta = args.beta.or_else(|| args.mocap.then_some(MOCAP_BETA));
    if let Some(b) = beta
        && !(b.is_finite() && b > 0.0)
    {
        bail!("--beta must be a positive number, got {b}");
    }
    let (retarget, actors) = match &args.actors {
        Some(path) => (None, actors_spec(path, args)?),
        None => (retarget_spec(args)?, Vec::new()),
    };
    let mut actors_wire = actors;
    for a in &mut actors_wire {
        a.beta = beta.unwrap_or(0.0);
        a.filter = filter.map(v1::MarkerFilter::from);
        a.refine = args.refine.map(|f| refine_wire(f.0));
        a.skinning = super::common::skinning_wire(args.skinning);
    }
    let with_actors = !actors_wire.is_empty();
    let model = args.model.clone().unwrap_or_default();
    let mut client = args.server.connect().await?;
    let request = if with_actors {
        v1::OpenRoomRequest {
            room: args.room.clone(),
            actors: actors_wire,
            ..Default::default()
        }
    } else {
        v1::OpenRoomRequest {
            room: args.room.clone(),
            model: model.clone(),
            beta: beta.unwrap_or(0.0),
            filter: filter.map(v1::MarkerFilter::from),
            retarget,
            refine: args.refine.map(|f| refine_wire(f.0)),
            skinning: super::common::skinning_wire(args.skinning),
            actors: Vec::new(),
        }
    };
    let opened = client
        .open_room(authorized(request, &args.admin.admin_token)?)
        .await
        .map_err(|s| anyhow::anyhow!("{}", s.message()))
        .with_context(|| match &args.actors {
            Some(path) => format!(
                "opening room {:?} of the actors of {}",
                args.room,
                path.display()
            ),
            None => format!("opening room {:?} on model {model:?}", args.room),
        })?
        .into_inner();
    let room = get_room(&mut client, &opened.room).await?;
    if with_actors {
        for line in actor_lines(&room) {
            eprintln!("room {:?}: {line}", room.room);
        }
        println!("{}", opened.publish_token);
        return Ok(());
    }
    eprintln!(
        "opened room {:?} on model {:?}: beta {}, filter {}, refinement {}, skinning {}{}",
        room.room,
        model,
        room.beta,
        print_filter(room.filter.as_ref()),
        print_refinement(room.refine.as_ref()),
        print_skinning(room.skinning),
        room.retarget.as_ref().map_or(String::new(), |r| format!(
            ", retargets {} markers ({})",
            r.markers.len(),
            r.units
        ))
    );
    // The token alone on stdout, for scripts: TOKEN=$(crease room open ...).
    println!("{}", opened.publish_token);
    Ok(())
}

/// One `[[actor]]` of an `--actors` file.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ActorEntry {
    name: String,
    model: String,
    #[serde(default)]
    side: String,
    #[serde(default)]
    mirror: String,
    #[serde(default)]
    performer: String,
    /// A marker map, relative to the actors file.
    map: Option<PathBuf>,
}

/// An `--actors` file.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ActorsFile {
    actor: Vec<ActorEntry>,
}

/// The actors of `--actors FILE`, each retargeting through its map the capture markers of
/// `--markers` / `--markers-from` / `--webxr` that the map reads (in the capture's order).
/// Options are left to the caller; the server checks names, sides and mirrors.
fn actors_spec(path: &std::path::Path, args: &OpenArgs) -> anyhow::Result<Vec<v1::Actor>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--actors {}", path.display()))?;
    let file: ActorsFile =
        toml::from_str(&text).with_context(|| format!("--actors {}", path.display()))?;
    if file.actor.is_empty() {
        bail!("--actors {}: no [[actor]] table", path.display());
    }
    let capture = capture_markers(args)?;
    let dir = path.parent().unwrap_or(std::path::Path::new("."));
    file.actor
        .into_iter()
        .map(|e| {
            let retarget = match (&e.map, &capture) {
                (None, _) => None,
                (Some(map), None) => bail!(
                    "--actors {}: actor {:?} retargets through {}: give the capture's markers (--markers-from RECORDING, --markers, --webxr or --mediapipe)",
                    path.display(),
                    e.name,
                    map.display()
                ),
                (Some(map), Some((markers, units))) => {
                    let map_path = dir.join(map);
                    let map_toml = std::fs::read_to_string(&map_path).with_context(|| {
                        format!("--actors {}: actor {:?}: map {}", path.display(), e.name, map_path.display())
                    })?;
                    let used = crease_mocap::map::MarkerMap::parse(&map_path, &map_toml)?.marker_names();
                    Some(v1::Retarget {
                        map_toml,
                        map_name: String::new(),
                        // A C3D label may carry a subject prefix (`Subject:RHAN`).
                        markers: markers
                            .iter()
                            .filter(|m| {
                                used.contains(*m)
                                    || m.rsplit(':').next().is_some_and(|s| used.contains(s))
                            })
                            .cloned()
                            .collect(),
                        units: units.clone(),
                    })
                }
            };
            Ok(v1::Actor {
                name: e.name,
                model: e.model,
                side: e.side,
                mirror: e.mirror,
                performer: e.performer,
                retarget,
                ..Default::default()
            })
        })
        .collect()
}

/// The capture's marker names and units from `--markers` / `--markers-from` / `--webxr` /
/// `--mediapipe`, if given.
fn capture_markers(args: &OpenArgs) -> anyhow::Result<Option<(Vec<String>, String)>> {
    Ok(match (&args.markers, &args.markers_from) {
        _ if args.webxr => Some((crease_hand::joint_map::capture_markers(), "m".to_owned())),
        _ if args.mediapipe => Some((
            crease_hand::mediapipe_map::mediapipe_markers(),
            "m".to_owned(),
        )),
        (Some(m), _) => Some((m.clone(), args.units.clone())),
        (None, Some(path)) => {
            let r = crease_mocap::Recording::read(path)
                .with_context(|| format!("--markers-from {}", path.display()))?;
            Some((r.names, r.units))
        }
        (None, None) => None,
    })
}

/// The room's `Retarget` from `--map` / `--map-name` and `--markers` / `--markers-from`.
fn retarget_spec(args: &OpenArgs) -> anyhow::Result<Option<v1::Retarget>> {
    let has_map = args.map.is_some() || args.map_name.is_some();
    let has_markers =
        args.markers.is_some() || args.markers_from.is_some() || args.webxr || args.mediapipe;
    match (has_map, has_markers) {
        (false, false) => return Ok(None),
        (true, false) => bail!(
            "--map needs the capture's marker names: --markers A,B,..., --markers-from RECORDING, --webxr or --mediapipe"
        ),
        (false, true) => {
            bail!("--markers, --markers-from, --webxr and --mediapipe need --map or --map-name")
        }
        (true, true) => {}
    }
    let map_toml = match &args.map {
        Some(path) => {
            std::fs::read_to_string(path).with_context(|| format!("--map {}", path.display()))?
        }
        None => String::new(),
    };
    let (markers, units) = capture_markers(args)?.context("the capture's markers")?;
    Ok(Some(v1::Retarget {
        map_toml,
        map_name: args.map_name.clone().unwrap_or_default(),
        markers,
        units,
    }))
}

/// One line per actor of a room of several (issue 38): name, side, performer, model, options
/// and capture.
fn actor_lines(room: &v1::RoomInfo) -> Vec<String> {
    room.actors
        .iter()
        .filter_map(|info| {
            let (a, m) = (info.actor.as_ref()?, info.model.as_ref()?);
            Some(format!(
                "actor {:?}{}{} on model {:?} ({} vertices, {} control points): beta {}, filter {}, refinement {}, skinning {}{}",
                a.name,
                if a.side.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", a.side)
                },
                if a.performer.is_empty() {
                    String::new()
                } else {
                    format!(" of performer {:?}", a.performer)
                },
                m.name,
                m.base_vertices,
                m.control_points.len(),
                a.beta,
                print_filter(a.filter.as_ref()),
                print_refinement(a.refine.as_ref()),
                print_skinning(a.skinning),
                a.retarget.as_ref().map_or(String::new(), |r| format!(
                    ", retargets {} markers ({})",
                    r.markers.len(),
                    r.units
                ))
            ))
        })
        .collect()
}

async fn info(args: &InfoArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let room = get_room(&mut client, &args.room).await?;
    if !room.actors.is_empty() {
        println!(
            "room {:?}: {} actors, {} subscribers, {} frames published",
            room.room,
            room.actors.len(),
            room.subscribers,
            room.published
        );
        for line in actor_lines(&room) {
            println!("  {line}");
        }
        return Ok(());
    }
    let model = room.model.unwrap_or_default();
    println!(
        "room {:?}: model {:?} ({} vertices, {} control points: {}), beta {}, filter {}, refinement {}, skinning {}, {} subscribers, {} frames published",
        room.room,
        model.name,
        model.base_vertices,
        model.control_points.len(),
        model
            .control_points
            .iter()
            .map(|c| c.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        room.beta,
        print_filter(room.filter.as_ref()),
        print_refinement(room.refine.as_ref()),
        print_skinning(room.skinning),
        room.subscribers,
        room.published
    );
    Ok(())
}

async fn close(args: &CloseArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    client
        .close_room(authorized(
            v1::CloseRoomRequest {
                room: args.room.clone(),
            },
            &args.admin.admin_token,
        )?)
        .await
        .map_err(|s| anyhow::anyhow!("{}", s.message()))
        .with_context(|| format!("closing room {:?}", args.room))?;
    eprintln!("closed room {:?}", args.room);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filter_specs() {
        assert_eq!(parse_filter("default").unwrap(), OneEuroParams::default());
        let p = parse_filter("2, 0.5, 1").unwrap();
        assert_eq!((p.min_cutoff_hz, p.beta, p.d_cutoff_hz), (2.0, 0.5, 1.0));
        assert!(
            parse_filter("1,2")
                .unwrap_err()
                .to_string()
                .contains("got 2")
        );
        assert!(
            parse_filter("0,1,1")
                .unwrap_err()
                .to_string()
                .contains("positive")
        );
        assert!(parse_filter("a,b,c").is_err());
    }
}
