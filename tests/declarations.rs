//! Every component's declared lines, tried from the declaration itself: every line
//! and every form of a line in forms (`provides laser N RESOLUTION ...`), one bad
//! value per argument (each refused at its file:line, naming what was expected),
//! each line with good values and with each number at both ends of its range
//! accepted, and `jderobot help` printing every form. Then, for the drivers whose
//! parsed settings are public, values at the ends of their ranges reach the
//! component unchanged (nothing clamped, nothing raised), and the documented
//! values are the declared ones.

use crate::common;

use jderobot::{
    conf::{
        ComponentConf, Kind,
        settings::{Arg, ArgType, Setting},
    },
    registry,
};

/// A word that `a` refuses, if there is one.
fn bad_word(a: &Arg) -> Option<String> {
    Some(match a.ty {
        ArgType::Int { max, .. } if max < i64::MAX => (max + 1).to_string(),
        ArgType::Int { .. } => "x".into(),
        ArgType::Float { max, .. } | ArgType::FloatOr { max, .. } if max < f64::MAX => {
            format!("{}", max * 2.0 + 1.0)
        }
        ArgType::Float { .. } | ArgType::FloatOr { .. } => "nan".into(),
        ArgType::Choice(_) => "no_such_choice".into(),
        ArgType::OnOff => "maybe".into(),
        ArgType::Interface => "lazer".into(),
        ArgType::Name => "1.5".into(),
        ArgType::Flags(_) => "no_such_flag".into(),
        ArgType::Kinds(_) => "no_such_kind".into(),
        ArgType::Numbers { max, .. } if max < f64::MAX => format!("{}", max * 2.0 + 1.0),
        ArgType::Numbers { .. } => "nan".into(),
        ArgType::Custom { check, .. } => {
            return CUSTOM_TRIES
                .iter()
                .find(|w| check(w).is_err())
                .map(|w| w.to_string());
        }
        ArgType::Path | ArgType::Word | ArgType::Rest => return None,
    })
}

/// Words tried on a `Custom` argument: it takes some and refuses others.
const CUSTOM_TRIES: &[&str] = &[
    "robot2",
    "lab/robot1/laser",
    "127.0.0.1",
    "position2d:1",
    "a*b",
    "a/b",
    "$x",
];

/// A word that `a` accepts (None: a `Flags` argument, left out).
fn good_word(a: &Arg) -> Option<String> {
    Some(match a.ty {
        ArgType::Int { min, max } => min.max(0).min(max).to_string(),
        ArgType::Float { min, max } | ArgType::FloatOr { min, max, .. } => {
            format!("{}", min.max(0.0).min(max))
        }
        ArgType::Choice(c) => c[0].to_string(),
        ArgType::OnOff => "on".into(),
        ArgType::Interface => "none".into(),
        ArgType::Name => "robot2".into(),
        ArgType::Flags(_) => return None,
        ArgType::Kinds(k) => k[0].name().into(),
        ArgType::Numbers { min, max } => format!("{}", min.max(0.0).min(max)),
        ArgType::Custom { check, .. } => {
            CUSTOM_TRIES.iter().find(|w| check(w).is_ok())?.to_string()
        }
        ArgType::Path | ArgType::Word | ArgType::Rest => "word".into(),
    })
}

/// The argument lists a line may take: its own, or each of its forms'.
fn shapes(s: &Setting) -> Vec<&'static [Arg]> {
    if s.forms.is_empty() {
        vec![s.args]
    } else {
        s.forms.iter().map(|f| f.args).collect()
    }
}

/// The line `KEY` + the good words of `args`, with word `i` replaced by `with`.
fn line(key: &str, args: &[Arg], replace: Option<(usize, &str)>) -> String {
    let mut words = vec![key.to_string()];
    for (k, a) in args.iter().enumerate() {
        match replace {
            Some((i, w)) if i == k => words.push(w.to_string()),
            _ => words.extend(good_word(a)),
        }
    }
    words.join(" ")
}

/// Whether `p` holds no problem of line 2 (a required line left out is another matter).
fn accepted(p: &[String]) -> bool {
    p.iter()
        .all(|e| !e.starts_with("t.conf:2: ") || e.contains(", and needs one: "))
}

#[test]
fn every_argument_of_every_form_refuses_a_bad_value_at_its_line() {
    let (mut tried, mut forms) = (0, 0);
    for (entry, decl) in common::declared() {
        let kind = entry.kind.to_string();
        for s in decl {
            forms += s.forms.len();
            for args in shapes(s) {
                for (i, a) in args.iter().enumerate() {
                    // A form's first word chooses the form: tried below.
                    if i == 0 && !s.forms.is_empty() {
                        continue;
                    }
                    let Some(bad) = bad_word(a) else { continue };
                    let l = line(s.key, args, Some((i, &bad)));
                    let p = common::line_problems(&kind, entry.name, &l);
                    // Where another form starts with the same word, the bad line
                    // may read as that form: it is refused all the same.
                    let first = args.first().and_then(good_word).unwrap_or_default();
                    let alike = shapes(s)
                        .iter()
                        .filter(|f| f.first().and_then(good_word) == Some(first.clone()))
                        .count();
                    let named = |e: &String| alike > 1 || e.contains(&format!("is `{bad}`"));
                    assert!(
                        p.iter().any(|e| e.starts_with("t.conf:2: ")
                            && named(e)
                            && e.contains("expected")),
                        "{} `{l}`: {p:?}",
                        entry.name
                    );
                    tried += 1;
                }
                // Too many words, where the line has an end.
                if !args.iter().any(|a| a.ty.takes_the_rest()) {
                    let l = format!("{} extra", line(s.key, args, None));
                    let p = common::line_problems(&kind, entry.name, &l);
                    assert!(
                        p.iter()
                            .any(|e| e.starts_with("t.conf:2: ") && e.contains("usage: ")),
                        "{} `{l}`: {p:?}",
                        entry.name
                    );
                }
            }
            if !s.forms.is_empty() {
                let l = format!("{} no_such_interface", s.key);
                let p = common::line_problems(&kind, entry.name, &l);
                assert!(
                    p.iter().any(|e| e.starts_with("t.conf:2: ")
                        && e.contains("not `no_such_interface`")
                        && e.contains(&s.usage())),
                    "{} `{l}`: {p:?}",
                    entry.name
                );
            }
        }
        let p = common::line_problems(&kind, entry.name, "no_such_line 1");
        assert!(
            p.iter().any(|e| e.starts_with("t.conf:2: ")
                && e.contains("`no_such_line`")
                && e.contains(&format!("jderobot help {}", entry.name))),
            "{}: {p:?}",
            entry.name
        );
    }
    assert!(tried > 100, "only {tried} bad values tried");
    assert!(forms >= 25, "only {forms} forms declared");
}

/// The lines a conf needs beside `key`'s for its component to be read at all:
/// every other required line, with good values, each on a line of its own.
fn required_besides(decl: &[Setting], key: &str) -> String {
    decl.iter()
        .filter(|s| s.required && s.key != key)
        .map(|s| format!("\n{}", line(s.key, shapes(s)[0], None)))
        .collect()
}

/// The ways a line of `args` may be written with good values: every argument
/// given, every optional group left out, and each word as a `/topic`.
fn variants(key: &str, args: &[Arg]) -> Vec<String> {
    let mut out = vec![line(key, args, None)];
    let mut required = vec![key.to_string()];
    let mut skipping = false;
    for a in args {
        skipping = a.optional || (skipping && !a.ty.takes_the_rest());
        if !skipping && !matches!(a.ty, ArgType::Flags(_)) {
            required.extend(good_word(a));
        }
    }
    out.push(required.join(" "));
    if args.iter().any(|a| matches!(a.ty, ArgType::Word)) {
        let mut words = vec![key.to_string()];
        for a in args {
            match a.ty {
                ArgType::Word => words.push("/topic".into()),
                _ => words.extend(good_word(a)),
            }
        }
        out.push(words.join(" "));
    }
    out.dedup();
    out
}

/// The walk of issue 49: every form of every line of every component, in each
/// argument count it advertises, with a name and a `/topic` where it takes a word,
/// and each number at both ends of its range, beside the component's other
/// required lines, goes through `jderobot check` (the declaration, then the
/// component's typed read): accepted, and never an `internal` answer.
#[test]
fn every_form_is_read_by_its_component_in_every_argument_count_and_at_both_ends() {
    let mut tried = 0;
    for (entry, decl) in common::declared() {
        let kind = entry.kind.to_string();
        for s in decl {
            let rest = required_besides(decl, s.key);
            for args in shapes(s) {
                let mut lines = variants(s.key, args);
                for (i, a) in args.iter().enumerate() {
                    let ends = match a.ty {
                        ArgType::Int { min, max } => [min.to_string(), max.to_string()],
                        ArgType::Float { min, max }
                        | ArgType::FloatOr { min, max, .. }
                        | ArgType::Numbers { min, max } => [format!("{min}"), format!("{max}")],
                        _ => continue,
                    };
                    for end in ends {
                        lines.push(line(s.key, args, Some((i, &end))));
                    }
                }
                for l in lines {
                    let p = common::line_problems(&kind, entry.name, &format!("{l}{rest}"));
                    assert!(
                        accepted(&p) && !p.iter().any(|e| e.contains("internal")),
                        "{} `{l}`: {p:?}",
                        entry.name
                    );
                    tried += 1;
                }
            }
        }
    }
    assert!(tried > 300, "only {tried} lines tried");
}

/// Issue 49's regression: `help gazebo` declares `provides laser SENSOR|/TOPIC [N
/// R]`, and the line `provides laser /lidar 360 1` stopped a run with
/// `internal: settings do not match their declaration: invalid type: integer
/// 360, expected a string`.
#[cfg(feature = "gazebo")]
#[test]
fn gazebo_reads_a_laser_on_a_topic_with_its_readings() {
    use jderobot::drivers::gazebo::{GzConf, Kind as Gz};
    let p = common::line_problems("driver", "gazebo", "provides laser /lidar 360 1");
    assert!(p.is_empty(), "{p:?}");
    let c = GzConf::parse(&driver("gazebo", "provides laser /lidar 360 1\n")).unwrap();
    assert_eq!(c.wants[0].kind, Gz::Laser(360, 1.0));
    assert_eq!(c.wants[0].target, "/lidar");
    assert_eq!(c.wants[0].fixed_topic().as_deref(), Some("/lidar"));
    let c = GzConf::parse(&driver(
        "gazebo",
        "provides laser front\nprovides ptencoders m\n",
    ))
    .unwrap();
    assert_eq!(c.wants[0].kind, Gz::Laser(180, 1.0));
    assert_eq!(
        (c.wants[1].kind.clone(), c.wants[1].iface.as_str()),
        (Gz::PtEncoders, "pantiltencoders")
    );
}

#[test]
fn help_prints_every_form_and_argument() {
    for (entry, decl) in common::declared() {
        let text = common::help(entry.name);
        assert!(text.contains(entry.summary), "{text}");
        for s in decl {
            assert!(text.contains(s.help), "help {}: {text}", entry.name);
            if let Some(d) = s.default {
                assert!(text.contains(&format!("default: {d}")), "{text}");
            }
            if s.forms.is_empty() {
                assert!(text.contains(&s.usage()), "help {}: {text}", entry.name);
            }
            for f in s.forms {
                assert!(
                    text.contains(&f.usage(s.key)) && text.contains(f.help),
                    "help {}: {text}",
                    entry.name
                );
            }
        }
    }
    let text = common::help("simulator");
    assert!(
        text.contains("provides laser [N RESOLUTION] [ROBOT]")
            && text.contains("N: a whole number between 1 and 720"),
        "{text}"
    );
    let text = common::help("gazebo");
    assert!(
        text.contains("N: a whole number between 1 and 3600"),
        "{text}"
    );
}

/// A conf of one driver section.
#[cfg_attr(not(feature = "simulator"), allow(dead_code))]
fn driver(name: &str, text: &str) -> ComponentConf {
    ComponentConf::from_text(Kind::Driver, name, text).unwrap()
}

/// The declared range of `key`'s argument `arg` (in form `form`, for a line in forms).
#[cfg_attr(not(feature = "simulator"), allow(dead_code))]
fn range(component: &str, key: &str, form: Option<&str>, arg: &str) -> (f64, f64) {
    let decl = registry::find(component)
        .and_then(|e| e.lines)
        .unwrap()
        .decl;
    let s = decl.iter().find(|s| s.key == key).unwrap();
    let args = match form {
        Some(f) => s.forms.iter().find(|x| x.name == f).unwrap().args,
        None => s.args,
    };
    match args.iter().find(|a| a.name == arg).unwrap().ty {
        ArgType::Int { min, max } => (min as f64, max as f64),
        ArgType::Float { min, max } | ArgType::FloatOr { min, max, .. } => (min, max),
        t => panic!("{key} {arg} is {t:?}"),
    }
}

#[cfg(feature = "simulator")]
#[test]
fn simulator_values_reach_the_simulation_unchanged() {
    use jderobot::drivers::simulator::Simulation;
    let (fov_min, fov_max) = range("simulator", "camera_fov", None, "FOV");
    let (r_min, r_max) = range("simulator", "radius", None, "R");
    let (n_min, n_max) = range("simulator", "provides", Some("laser"), "N");
    let (res_min, res_max) = range("simulator", "provides", Some("laser"), "RESOLUTION");
    let (w_min, w_max) = range("simulator", "provides", Some("varcolor"), "W");
    for (fov, radius, n, res, w) in [
        (fov_min, r_min, n_min, res_min, w_min),
        (0.5, 250.0, 360.0, 0.5, 640.0),
        (fov_max, r_max, n_max, res_max, w_max),
    ] {
        let c = driver(
            "simulator",
            &format!(
                "robot r1\nrobot r2 0 0 0\ncamera_fov {fov}\nradius {radius}\n\
                 provides laser {n} {res} r2\nprovides varcolorA {w} {w} r2\nprovides motors\n"
            ),
        );
        let s = Simulation::parse(&c).unwrap();
        let m = &s.sim.robots[1].model;
        assert_eq!(m.camera_fov, fov, "camera_fov {fov} arrives as given");
        assert_eq!(m.radius, radius);
        assert_eq!((m.laser_count as f64, m.laser_resolution), (n, res));
        assert_eq!(
            s.provides[1].cameras,
            vec![("varcolorA.r2".into(), w as u32, w as u32)]
        );
        assert_eq!(s.provides[0].motors.as_deref(), Some("motors"));
    }
    // Beyond the ends: refused, naming the range (4.3's `camera_fov 0.5` was raised to 1).
    for (text, want) in [
        ("camera_fov 170", "between 0.001 and 169.999 deg"),
        ("radius 100001", "between 0.001 and 100000 mm"),
        ("provides laser 721 1", "between 1 and 720"),
        ("provides laser 180 1 nobody", "no robot called `nobody`"),
    ] {
        let e = Simulation::parse(&driver("simulator", text))
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{text}: {e}");
    }
}

#[cfg(feature = "player")]
#[test]
fn player_values_reach_the_driver_unchanged() {
    use jderobot::drivers::player::{PlayerConf, Provided};
    let (t_min, t_max) = range("player", "timeout", None, "MS");
    let (n_min, n_max) = range("player", "provides", Some("laser"), "N");
    for (t, n) in [(t_min, n_min), (t_max, n_max)] {
        let c = driver(
            "player",
            &format!(
                "hostname h port 7000\ntimeout {t}\nprovides laser {n} 2 index 1 r2\n\
                 provides encoders device position2d:3\n"
            ),
        );
        let p = PlayerConf::parse(&c).unwrap();
        assert_eq!((p.host.as_str(), p.port), ("h", 7000));
        assert_eq!(p.timeout.as_millis() as f64, t);
        assert_eq!(p.wants[0].kind, Provided::Laser(n as usize, 2.0));
        assert_eq!(
            (p.wants[0].index, p.wants[0].name.as_str()),
            (Some(1), "laser.r2")
        );
        assert_eq!(p.wants[1].device.map(|d| d.1), Some(Some(3)));
    }
    // The default is the declared one.
    let decl = registry::find("player").and_then(|e| e.lines).unwrap().decl;
    let default = decl.iter().find(|s| s.key == "timeout").unwrap().default;
    let p = PlayerConf::parse(&driver("player", "provides motors\n")).unwrap();
    assert_eq!(Some(p.timeout.as_millis().to_string().as_str()), default);
}

#[cfg(all(
    feature = "imagefile",
    feature = "gige",
    feature = "opencv",
    feature = "video4linux2",
    feature = "firewire",
    feature = "mplayer",
    feature = "networkclient"
))]
#[test]
fn image_sizes_reach_the_drivers_unchanged() {
    let (w_min, w_max) = range("imagefile", "provides", Some("varcolor"), "W");
    for w in [w_min, w_max] {
        let c = driver("imagefile", &format!("provides varcolorA f.png {w} 1\n"));
        let s = jderobot::drivers::imagefile::parse(&c).unwrap();
        assert_eq!(
            s[0].0.fit,
            jderobot::media::stills::Fit::Scale(w as u32, 1),
            "imagefile {w}"
        );
        let c = driver("gige", &format!("provides varcolorA Fake_1 {w} 1 Mono8\n"));
        let s = jderobot::drivers::gige::parse(&c).unwrap();
        assert_eq!(s[0].size, Some((w as u32, 1)));
        assert_eq!(s[0].pixel_format.as_deref(), Some("Mono8"));
    }
    let c = driver(
        "opencv",
        "provides varcolorA videofile c.avi 16384 1 unpaced loop\nprovides varcolorB image i.png autosize\n",
    );
    let s = jderobot::drivers::opencv::parse(&c).unwrap();
    assert_eq!(
        (s[0].0.size, s[0].0.repeat, s[0].0.pace),
        (Some((16384, 1)), true, false)
    );
    assert_eq!(s[1].0.size, None);
    let c = driver(
        "video4linux2",
        "provides varcolorA /dev/video0 255 8192 1\nprovides colorB /dev/video1 0\n",
    );
    let s = jderobot::drivers::video4linux2::parse(&c, false).unwrap();
    assert_eq!((s[0].input, s[0].width, s[0].height), (255, 8192, 1));
    let c = driver("video4linux", "provides varcolorA /dev/video0 640 480\n");
    let s = jderobot::drivers::video4linux2::parse(&c, true).unwrap();
    assert_eq!((s[0].input, s[0].width, s[0].height), (0, 640, 480));
    let c = driver(
        "firewire",
        "provides varcolorA 63 8192 1 autofocus_on\nprovides colorB 1\nbayer 63 GRBG\n",
    );
    let s = jderobot::drivers::firewire::parse(&c).unwrap();
    assert_eq!(
        (s[0].cam, s[0].width, s[0].height, s[0].autofocus),
        (63, 8192, 1, Some(true))
    );
    assert!(s[0].bayer.is_some() && s[1].bayer.is_none());
    let c = driver(
        "mplayer",
        "provides varcolorA c.avi 8192 2 repeat_on unpaced\nprovides colorB v4l /dev/video0 s-video\n",
    );
    let s = jderobot::drivers::mplayer::parse(&c).unwrap();
    assert_eq!(
        (s[0].0.width, s[0].0.height, s[0].0.repeat, s[0].0.pace),
        (8192, 2, true, false)
    );
    let c = driver(
        "networkclient",
        "provides varcolorA h 1 4294967295 8192 1\nprovides ptmotors h 65535\n",
    );
    let s = jderobot::drivers::networkclient::ClientConf::parse(&c).unwrap();
    assert_eq!(
        (s.remotes[0].netid, s.remotes[0].size),
        (Some(u32::MAX), Some((8192, 1)))
    );
    assert_eq!(
        (s.remotes[1].name.as_str(), s.remotes[1].port),
        ("pantiltmotors", 65535)
    );
}

/// Components bring their own shell commands and `ps` lines (a test component here).
#[path = "declarations/registered.rs"]
mod registered;

/// A docs page's `<!-- help NAME -->` block is `jderobot help NAME`, from the
/// declaration: the documented ranges and defaults are the declared ones.
#[test]
fn documented_lines_are_the_declared_ones() {
    let mut checked = 0;
    for entry in std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/docs")).unwrap() {
        let path = entry.unwrap().path();
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue;
        };
        let mut rest = text.as_str();
        while let Some(at) = rest.find("<!-- help ") {
            let after = &rest[at + "<!-- help ".len()..];
            let name = after.split_whitespace().next().unwrap();
            let body = after.split_once("```text\n").unwrap().1;
            let body = body.split_once("```").unwrap().0;
            assert_eq!(
                body,
                common::help(name),
                "{}: the `help {name}` block differs from `jderobot help {name}`; paste it again",
                path.display()
            );
            checked += 1;
            rest = &after[name.len()..];
        }
    }
    assert!(
        checked >= 1,
        "no docs page shows a component's declared lines"
    );
}
