//! The wire rule of ARCHITECTURE.md, kept (issue 37): `crease-proto` is the only crate that
//! builds wire shapes, and it stays a contract, not a runtime.
//!
//! - No library source (`*/src/**/*.rs`) of a crate other than `crease-proto` constructs a
//!   generated message of `crease.v1` (a `v1::Name { ... }` literal or `v1::Name::default()`,
//!   also through a `use ...::v1::Name` import), except the transport modules of
//!   [`TRANSPORT`], which answer calls and so build replies where they are made. Tests are
//!   clients and may build any message.
//! - `crease-proto`'s sources never name the predictor that runs frames (`Predictor`,
//!   `FrameContext`) or the glTF writer (`gltf_export`): exporting and re-predicting takes is
//!   the server's and the command line's business, not the contract's.
//! - In the server's library, only the gRPC service and `server::status` name tonic's
//!   `Status`: below the transports errors are typed.
//!
//! The message names are read from `proto/crease/v1/*.proto`; the sources are scanned as
//! tokens (`source_scan`), comments, strings and unit-test modules dropped.

use crate::source_scan;

use std::collections::BTreeSet;
use std::path::Path;

use source_scan::{
    Tok, drop_test_modules, matching_brace, paths_from, relative, repo, rust_files, tokens,
    workspace_members,
};

/// The transport modules that may construct wire messages, each with why: they answer (or
/// make) the calls, so the reply is built where it is sent.
const TRANSPORT: [(&str, &str); 5] = [
    (
        "server/src/grpc.rs",
        "the gRPC handlers build their replies",
    ),
    ("server/src/ws.rs", "the WebSocket handler builds its acks"),
    (
        "server/src/http.rs",
        "the HTTP handlers build their documents",
    ),
    (
        "remote/src/client.rs",
        "the client library's calls build their requests",
    ),
    (
        "remote/src/mesh_stream.rs",
        "the client library's subscription request",
    ),
];

/// What `crease-proto` never names: the predictor that runs frames and the glTF writer.
const PROTO_NEVER: [&str; 3] = ["Predictor", "FrameContext", "gltf_export"];

/// Files that still build wire messages outside the transport, each with why. The test fails
/// on any other, and on one of these once it is clean (so the list only shrinks).
const KNOWN: [(&str, &str); 10] = [
    (
        "bridge/src/natnet/mod.rs",
        "a marker frame built where the datagram is read; to be a crease-proto conversion",
    ),
    (
        "bridge/src/vmc/frames.rs",
        "a marker frame built where the bundle is read; to be a crease-proto conversion",
    ),
    (
        "bench-net/src/load.rs",
        "room requests built at the call; to go through crease-remote's helpers",
    ),
    (
        "bench-net/src/soak/mod.rs",
        "room requests and frames built at the call; to go through crease-remote",
    ),
    (
        "bench-net/src/chaos/mod.rs",
        "the rooms' OpenRoom requests built at the call, as the soak's; to go through crease-remote",
    ),
    (
        "bench-net/src/chaos/takes.rs",
        "the take requests built at the call (crease-remote has no take calls yet); to go through crease-remote",
    ),
    (
        "client/src/commands/remote_synth.rs",
        "the batch request built at the call; to go through crease-remote's helpers",
    ),
    (
        "client/src/commands/room.rs",
        "the room requests built from the flags; to go through crease-remote's helpers",
    ),
    (
        "client/src/commands/take.rs",
        "the take requests built at the call; to go through crease-remote's helpers",
    ),
    (
        "client/src/commands/watch.rs",
        "a received frame re-wrapped for the capture file; to be a crease-proto helper",
    ),
];

/// The names of every message of `crease.v1` (nested ones too), from the `.proto` files.
fn message_names(root: &Path) -> BTreeSet<String> {
    let dir = root.join("proto/crease/v1");
    let mut names = BTreeSet::new();
    for e in std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .flatten()
    {
        if e.path().extension().is_none_or(|x| x != "proto") {
            continue;
        }
        let text = std::fs::read_to_string(e.path()).unwrap();
        for line in text.lines() {
            if let Some(rest) = line.trim().strip_prefix("message ") {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                names.insert(name);
            }
        }
    }
    assert!(
        names.len() > 30,
        "{}: expected the crease.v1 messages, found {names:?}",
        dir.display()
    );
    names
}

/// Where `toks` construct a message of `messages`: `(message, token index)` each.
fn constructions(toks: &[Tok], messages: &BTreeSet<String>) -> Vec<(String, usize)> {
    // Names a `use` brings in from a `v1` path (`use crease_proto::v1::{Frame, Topology};`),
    // and whether one imports all of `v1`.
    let mut imported: BTreeSet<String> = BTreeSet::new();
    let mut glob = false;
    for (i, t) in toks.iter().enumerate() {
        if *t != Tok::Ident("use".into()) {
            continue;
        }
        let (paths, next) = paths_from(toks, i + 1);
        for p in paths {
            let Some(v1) = p.iter().position(|s| s == "v1") else {
                continue;
            };
            match p.last() {
                Some(last) if messages.contains(last) && v1 + 1 < p.len() => {
                    imported.insert(last.clone());
                }
                _ => {}
            }
            if p.len() == v1 + 1 && toks.get(next) == Some(&Tok::Punct("*")) {
                glob = true;
            }
        }
        if toks[i + 1..next.min(toks.len())].contains(&Tok::Punct("*"))
            && toks[i + 1..next.min(toks.len())].contains(&Tok::Ident("v1".into()))
        {
            glob = true;
        }
    }
    let mut found = Vec::new();
    for (i, t) in toks.iter().enumerate() {
        let Tok::Ident(name) = t else { continue };
        if !messages.contains(name) {
            continue;
        }
        // The path this name ends: walk back over `segment ::` pairs.
        let mut first = i;
        let mut through_v1 = false;
        while first >= 2 && toks[first - 1] == Tok::Punct("::") {
            if let Tok::Ident(seg) = &toks[first - 2] {
                through_v1 |= seg == "v1";
                first -= 2;
            } else {
                break;
            }
        }
        let bare = first == i;
        if !(through_v1 || (bare && (glob || imported.contains(name)))) {
            continue;
        }
        let literal = toks.get(i + 1) == Some(&Tok::Punct("{"));
        let default = toks.get(i + 1) == Some(&Tok::Punct("::"))
            && toks.get(i + 2) == Some(&Tok::Ident("default".into()))
            && toks.get(i + 3) == Some(&Tok::Punct("("));
        if default {
            found.push((name.clone(), i));
            continue;
        }
        if !literal {
            continue;
        }
        // A type before a block is no construction: `-> v1::Frame {`, `impl ... for v1::X {`,
        // `let v1::X { a, .. } = x;`, nor is a pattern (`v1::X { .. } => ...`).
        // (A reference type's `&` and `mut` are part of the type: `-> &v1::Frame {`.)
        let mut k = first;
        while k > 0 && (toks[k - 1] == Tok::Punct("&") || toks[k - 1] == Tok::Ident("mut".into())) {
            k -= 1;
        }
        let before = k.checked_sub(1).map(|k| &toks[k]);
        let type_or_pattern = matches!(before, Some(Tok::Punct("->")))
            || matches!(before, Some(Tok::Ident(k))
                if ["for", "impl", "let", "struct", "enum"].contains(&k.as_str()));
        // After the braces, past the parentheses a pattern may close (`Some(Ok(v1::X { .. }))`).
        let mut end = matching_brace(toks, i + 1);
        while toks.get(end) == Some(&Tok::Punct(")")) {
            end += 1;
        }
        let after = toks.get(end);
        let pattern = matches!(
            after,
            Some(Tok::Punct("=>")) | Some(Tok::Punct("|")) | Some(Tok::Punct("="))
        ) || matches!(after, Some(Tok::Ident(k)) if k == "if");
        if !type_or_pattern && !pattern {
            found.push((name.clone(), i));
        }
    }
    found
}

#[test]
fn only_crease_proto_and_the_transport_modules_construct_wire_messages() {
    let root = repo();
    let messages = message_names(&root);
    let mut offenders: Vec<(String, String)> = Vec::new();
    for member in workspace_members(&root) {
        if member == "proto" {
            continue;
        }
        let mut files = Vec::new();
        rust_files(&root.join(&member).join("src"), &mut files);
        files.sort();
        for f in files {
            let rel = relative(&root, &f);
            if TRANSPORT.iter().any(|(t, _)| *t == rel) {
                continue;
            }
            let text = std::fs::read_to_string(&f).unwrap();
            let toks = drop_test_modules(tokens(&text));
            let built: BTreeSet<String> = constructions(&toks, &messages)
                .into_iter()
                .map(|(m, _)| m)
                .collect();
            if !built.is_empty() {
                offenders.push((rel, built.into_iter().collect::<Vec<_>>().join(", ")));
            }
        }
    }
    let known: Vec<&str> = KNOWN.iter().map(|(f, _)| *f).collect();
    let new: Vec<String> = offenders
        .iter()
        .filter(|(f, _)| !known.contains(&f.as_str()))
        .map(|(f, m)| format!("{f}: {m}"))
        .collect();
    assert!(
        new.is_empty(),
        "wire messages built outside crease-proto and the transport modules (add a conversion \
         to crease-proto and call it):\n  {}",
        new.join("\n  ")
    );
    for (file, why) in KNOWN {
        assert!(
            offenders.iter().any(|(f, _)| f == file),
            "{file} builds no wire message any more: remove it from KNOWN ({why})"
        );
    }
}

/// ARCHITECTURE.md's "no `tonic::Status` below the transports" (issue 37): in the server's
/// library sources only the gRPC service and the one status table (`server::status`) name
/// tonic's `Status`; everything else returns typed errors that the table maps.
#[test]
fn only_grpc_and_the_status_table_name_tonic_status() {
    const ALLOWED: [&str; 2] = ["server/src/grpc.rs", "server/src/status.rs"];
    let root = repo();
    let mut files = Vec::new();
    rust_files(&root.join("server/src"), &mut files);
    files.sort();
    let mut found = Vec::new();
    for f in files {
        let rel = relative(&root, &f);
        let toks = drop_test_modules(tokens(&std::fs::read_to_string(&f).unwrap()));
        let ident = |name: &str| toks.iter().any(|t| matches!(t, Tok::Ident(n) if n == name));
        if ident("tonic") && ident("Status") && !ALLOWED.contains(&rel.as_str()) {
            found.push(rel);
        }
    }
    assert!(
        found.is_empty(),
        "tonic::Status named below the transports (return a typed error and map it in \
         server/src/status.rs): {found:?}"
    );
}

#[test]
fn crease_proto_does_not_run_the_predictor_or_write_gltf() {
    let root = repo();
    let mut files = Vec::new();
    rust_files(&root.join("proto/src"), &mut files);
    files.push(root.join("proto/build.rs"));
    let mut found = Vec::new();
    for f in files {
        let Ok(text) = std::fs::read_to_string(&f) else {
            continue;
        };
        // The predictor's options (`predictor::Refinement`) are data a conversion may fill;
        // running it takes a `Predictor` and its `FrameContext`.
        for t in tokens(&text) {
            if let Tok::Ident(name) = t
                && PROTO_NEVER.contains(&name.as_str())
            {
                found.push(format!("{}: {name}", relative(&root, &f)));
            }
        }
    }
    assert!(
        found.is_empty(),
        "crease-proto is the wire contract; it runs the predictor or writes glTF:\n  {}",
        found.join("\n  ")
    );
}

#[test]
fn literals_defaults_and_imports_count_types_and_patterns_do_not() {
    let messages: BTreeSet<String> = ["Frame", "RoomEntry", "Topology", "Vec3"]
        .map(str::to_owned)
        .into();
    let found = |src: &str| -> Vec<String> {
        constructions(&drop_test_modules(tokens(src)), &messages)
            .into_iter()
            .map(|(m, _)| m)
            .collect()
    };
    // Built: a literal through the module, a default, an imported name.
    assert_eq!(
        found("fn f() -> u8 { let x = v1::Frame { a: 1 }; 0 }"),
        ["Frame"]
    );
    assert_eq!(
        found("fn f() { g(crease_proto::v1::RoomEntry::default()) }"),
        ["RoomEntry"]
    );
    assert_eq!(
        found("use crease_proto::v1::{Topology, frame}; fn f() { h(Topology { n: 2 }) }"),
        ["Topology"]
    );
    assert_eq!(
        found("use crease_proto::v1::*; fn f() { Vec3 { x: 0.0 } }"),
        ["Vec3"]
    );
    // Not built: types before a body, impls, patterns, our own types of the same name,
    // comments, strings and unit tests.
    assert!(found("fn f() -> v1::Frame { make() }").is_empty());
    assert!(found("fn f(&self) -> &v1::Frame { &self.frame }").is_empty());
    assert!(found("fn f(&mut self) -> &mut v1::Frame { &mut self.frame }").is_empty());
    assert_eq!(found("fn f() { g(&v1::Frame { a: 1 }) }"), ["Frame"]);
    assert!(found("impl From<A> for v1::Frame { fn from(a: A) -> Self { a.0 } }").is_empty());
    assert!(found("fn f(x: X) { match x { v1::Frame { a, .. } => a, _ => 0 } }").is_empty());
    assert!(found("fn f(x: X) { let v1::Frame { a, .. } = x; }").is_empty());
    assert!(found("fn f(x: X) { match x { Some(Ok(v1::Frame { a })) => a, _ => 0 } }").is_empty());
    assert!(found("fn f(x: X) { if let Ok(v1::Frame { a }) = x { a } else { 0 } }").is_empty());
    assert!(found("struct Frame { a: u8 } fn f() -> Frame { Frame { a: 1 } }").is_empty());
    assert!(
        found(
            "// v1::Frame { a: 1 }\n const S: &str = \"v1::Frame { }\";\n\
             #[cfg(test)] mod tests { fn t() { v1::Frame { a: 1 }; } }"
        )
        .is_empty()
    );
}
