//! Deterministic replay: introrob (VFF) drives the simulator in lock-step while the
//! recorder records laser, encoders and motors; then the replay (`stepped motors`)
//! drives introrob from the recording, and introrob gives the same commands, one
//! for one. Both runs are the real binary, headless.
#![cfg(all(
    feature = "recorder",
    feature = "replay",
    feature = "simulator",
    feature = "introrob"
))]

use crate::common::world_path;

use std::{path::Path, process::Command};

use jderobot::{
    interfaces::Motors,
    mcapfmt::{self, Recorded, Summary},
};

const BIN: &str = env!("CARGO_BIN_EXE_jderobot");

const INTROROB: &str = "schema introrob\nbehaviour vff\ntarget 5000 2200\nmax_v 400\nmax_w 40\n\
     cycle 100\nsonars none\nbumpers none\ncamera none\nend_schema\n";

fn run(dir: &Path, name: &str, conf: &str, secs: f64) {
    let path = dir.join(name);
    std::fs::write(&path, conf).unwrap();
    let out = Command::new(BIN)
        .args(["--headless", "--no-shell", "--for", &secs.to_string()])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The motors commands of a file, in order.
fn commands(path: &Path) -> Vec<Motors> {
    let (_, bytes) = Summary::read(path).unwrap();
    let mut v = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic != "motors" {
            continue;
        }
        match mcapfmt::decode(
            &m.channel.topic,
            jderobot::interfaces::Kind::Motors,
            &m.data,
        )
        .unwrap()
        .value
        {
            Recorded::Motors(c) => v.push(c),
            other => panic!("{other:?}"),
        }
    }
    v
}

#[test]
fn introrob_gives_the_same_commands_on_a_lockstep_replay() {
    let dir = tempfile::tempdir().unwrap();
    run(
        dir.path(),
        "live.conf",
        &format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nstepped 100\nend_driver\n{INTROROB}\
             service recorder\nfile live.mcap\nrecords laser encoders motors\nend_service\n\
             load_driver simulator\nload_service recorder\nload_schema introrob\nrun introrob\n",
            world_path("simple.world")
        ),
        6.0,
    );
    run(
        dir.path(),
        "replay.conf",
        &format!(
            "driver replay\nfile live.mcap\nstepped motors\nend_driver\n{INTROROB}\
             service recorder\nfile replay.mcap\nrecords motors\nend_service\n\
             load_driver replay\nload_service recorder\nload_schema introrob\nrun introrob\n"
        ),
        6.0,
    );
    let live = commands(&dir.path().join("live.mcap"));
    let replay = commands(&dir.path().join("replay.mcap"));
    assert!(
        live.len() >= 20 && replay.len() >= 20,
        "{} live, {} replayed commands",
        live.len(),
        replay.len()
    );
    // The robot moved: the commands are not all the same.
    assert!(
        live.windows(2).any(|w| w[0] != w[1]),
        "introrob never changed its command"
    );
    // Align the two (each recorder started 0.3 s after its run) and compare: the
    // first commands of each run may have seen no data yet; after them, one for one.
    let best = (-20i64..=20)
        .map(|off| {
            let pairs: Vec<(usize, usize)> = (0..replay.len())
                .filter_map(|j| {
                    let i = j as i64 + off;
                    (i >= 0 && (i as usize) < live.len()).then_some((i as usize, j))
                })
                .collect();
            let equal = pairs
                .iter()
                .skip(3)
                .filter(|(i, j)| live[*i] == replay[*j])
                .count();
            (equal, pairs.len().saturating_sub(3), off)
        })
        .max()
        .unwrap();
    let (equal, compared, off) = best;
    assert!(compared >= 15, "only {compared} commands overlap");
    // Lock-step holds while each run answers a command within introrob's 100 ms
    // cycle; a machine loaded enough to miss that once may cost a pair or two.
    assert!(
        equal * 10 >= compared * 9,
        "offset {off}: {equal} of {compared} commands equal\nlive {live:?}\nreplay {replay:?}"
    );
    eprintln!("offset {off}: {equal} of {compared} commands equal");
}
