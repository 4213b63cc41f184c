//! fuzzy: the .fzz format, 4.3's inference (the manual's example), Mamdani, save.

use std::path::Path;

use jderobot::fuzzy::{Controller, FuzzyError, Inference, Trapezoid};

#[test]
fn manual_example_gives_minus_25_with_two_rules() {
    let mut c = Controller::from_file("assets/fuzzy/example.fzz").unwrap();
    assert_eq!(c.name, "fuzzy_controller");
    assert_eq!(c.rule_count(), 5);
    assert!(c.set_input("fuzzyvar1", 12000.0));
    assert!(c.set_input("fuzzyvar2", 500.0));
    assert_eq!(c.output("fuzzyvar3"), Some((-25.0, 2)));
    assert!(!c.set_input("nosuchvar", 1.0));
    assert_eq!(c.output("nosuchvar"), None);
}

#[test]
fn jde_inference_hand_computed() {
    let mut c = Controller::from_file("assets/fuzzy/example.fzz").unwrap();
    // var1 = 10000: valuename1 at 0.5; var2 = 550: valuename4 at 1.
    c.set_input("fuzzyvar1", 10000.0);
    c.set_input("fuzzyvar2", 550.0);
    // R1: a = 0.5 -> clipped centroid of valuename7 (symmetric) = -32.5;
    // R4: a = 0.5 -> centroid of valuename8 = -17.5. Mean: -25.
    let (v, n) = c.output("fuzzyvar3").unwrap();
    assert_eq!(n, 2);
    assert!((v + 25.0).abs() < 1e-4, "{v}");
    // A non-symmetric clipped trapezoid, by hand: (0,10,10,40) at 0.5.
    let t = Trapezoid([0.0, 10.0, 10.0, 40.0]);
    // m1 = 10*.25/2 = 1.25 @ 3.333; plateau W = 40 - 15 - 5 = 20, m2 = 10 @ 15;
    // m3 = 30*.25/2 = 3.75 @ 30. Centroid = (4.1667 + 150 + 112.5) / 15.
    assert!((t.clipped_centroid(0.5) - 266.666_67 / 15.0).abs() < 1e-3);
    assert_eq!(Trapezoid([5.0, 5.0, 5.0, 5.0]).clipped_centroid(1.0), 5.0);
    // No rule fires -> None (4.3 returned -1).
    c.set_input("fuzzyvar1", 50000.0);
    c.set_input("fuzzyvar2", 5000.0);
    assert_eq!(c.output("fuzzyvar3"), None);
}

#[test]
fn membership_matches_43() {
    let t = Trapezoid([300.0, 500.0, 600.0, 800.0]);
    assert_eq!(t.membership(300.0), 0.0);
    assert_eq!(t.membership(400.0), 0.5);
    assert_eq!(t.membership(500.0), 1.0);
    assert_eq!(t.membership(700.0), 0.5);
    assert_eq!(t.membership(800.0), 0.0);
    let s = Trapezoid([0.0, 0.0, 0.0, 0.0]);
    assert_eq!((s.membership(0.0), s.membership(0.001)), (1.0, 0.0));
}

#[test]
fn mamdani_mode_from_file_and_api() {
    let text =
        std::fs::read_to_string("assets/fuzzy/example.fzz").unwrap() + "defuzzificacion mamdani\n";
    let mut c = Controller::parse(&text, Path::new("m.fzz")).unwrap();
    assert_eq!(c.inference(), Inference::Mamdani);
    c.set_input("fuzzyvar1", 12000.0);
    c.set_input("fuzzyvar2", 500.0);
    // Both fired sets at full height, disjoint and equal areas: centroid = mean = -25.
    let (v, n) = c.output("fuzzyvar3").unwrap();
    assert_eq!(n, 2);
    assert!((v + 25.0).abs() < 1e-4, "{v}");
    // min AND and max aggregation: var1 = 10000 (0.5), var2 = 400 (0.5 for valuename4).
    c.set_input("fuzzyvar1", 10000.0);
    c.set_input("fuzzyvar2", 400.0);
    // R1: min(0.5, 0.5) = 0.5 on valuename7; R4: 0.5 on valuename8: mirror images of
    // one clipped shape, so the centroid is again -25.
    assert!((c.output("fuzzyvar3").unwrap().0 + 25.0).abs() < 1e-4);
    c.set_inference(Inference::Jde);
    // 4.3: product 0.25 for R1 vs 0.5 for R4 -> (0.25*-32.5 + 0.5*-17.5)/0.75.
    let (v, _) = c.output("fuzzyvar3").unwrap();
    assert!(
        (v - (0.25 * -32.5 + 0.5 * -17.5) / 0.75).abs() < 1e-4,
        "{v}"
    );
}

#[test]
fn parse_errors_have_file_and_line() {
    let p = Path::new("bad.fzz");
    let cases = [
        (
            "controlador c\netiqueta v l = 1 2 3\n",
            "bad.fzz:2: expected `etiqueta VARIABLE LABEL = p0 p1 p2 p3`",
        ),
        ("etiqueta v l = 1 x 3 4\n", "bad.fzz:1: `x` is not a number"),
        (
            "etiqueta v l = 4 3 2 1\n",
            "bad.fzz:1: label v l has parameters out of order",
        ),
        (
            "etiqueta v l = 1 2 3 4\netiqueta v l = 1 2 3 4\n",
            "bad.fzz:2: label v l is defined twice",
        ),
        (
            "etiqueta v l = 1 2 3 4\nIF ( w = l ) THEN ( v = l )\n",
            "bad.fzz:2: variable `w` has no labels",
        ),
        (
            "etiqueta v l = 1 2 3 4\nIF ( v = l ) OR ( v = l ) THEN ( v = l )\n",
            "bad.fzz:2: OR is not supported",
        ),
        (
            "etiqueta v l = 1 2 3 4\nIF ( v = l ) THEN\n",
            "bad.fzz:2: expected `IF ( var = label )",
        ),
        (
            "etiqueta v l = 1 2 3 4\nIF v = l THEN ( v = l )\n",
            "bad.fzz:2: expected `IF ( var = label )",
        ),
        ("hello\n", "bad.fzz:1: unknown line start `hello`"),
        (
            "defuzzificacion fast\n",
            "bad.fzz:1: expected `defuzzificacion jde` or `defuzzificacion mamdani`",
        ),
    ];
    for (text, want) in cases {
        let e = Controller::parse(text, p).unwrap_err().to_string();
        assert!(e.starts_with(want), "{text:?}: got {e}");
    }
    let e = Controller::parse("# only a comment\n", p).unwrap_err();
    assert!(matches!(e, FuzzyError::Invalid { .. }), "{e}");
    assert!(matches!(
        Controller::from_file("/no/such.fzz"),
        Err(FuzzyError::Io { .. })
    ));
}

#[test]
fn lenient_mode_skips_the_bad_lines_of_test_fzz() {
    assert!(Controller::from_file("assets/fuzzy/test.fzz").is_err());
    let (mut c, warnings) = Controller::from_file_lenient("assets/fuzzy/test.fzz").unwrap();
    let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
    assert_eq!(lines, vec![12, 18, 31], "{warnings:?}");
    assert!(warnings[0].message.contains("defined twice"));
    assert!(warnings[1].message.contains("out of order"));
    assert!(warnings[2].message.contains("humedad"));
    assert_eq!(c.rule_count(), 5);
    // The first definition of `fria` is kept.
    assert_eq!(
        c.label("temperatura", "fria").unwrap().0,
        [-10.0, -10.0, 12.0, 18.0]
    );
    // 4.3's example.c inputs.
    c.set_input("temperatura", 20.2);
    c.set_input("puerta", 15.0);
    let (v, n) = c.output("potencia").unwrap();
    assert!(n >= 2 && v > 0.0 && v < 100.0, "{v} {n}");
}

#[test]
fn chained_controllers_infer_internal_variables() {
    let text = "controlador chain\n\
        etiqueta a low = 0 0 0 10\netiqueta a high = 0 10 10 10\n\
        etiqueta b low = 0 0 0 100\netiqueta b high = 0 100 100 100\n\
        etiqueta c small = -1 -1 -1 -1\netiqueta c big = 1 1 1 1\n\
        IF ( a = high ) THEN ( b = high )\nIF ( b = high ) THEN ( c = big )\n";
    let mut c = Controller::parse(text, Path::new("chain")).unwrap();
    c.set_input("a", 10.0);
    assert_eq!(c.output("c"), Some((1.0, 1)));
    // An input never set makes its rules not fire.
    c.clear_input("a");
    assert_eq!(c.output("c"), None);
}

#[test]
fn save_loads_back_the_same_controller() {
    let dir = tempfile::tempdir().unwrap();
    for (file, lenient) in [
        ("assets/fuzzy/example.fzz", false),
        ("assets/fuzzy/test.fzz", true),
    ] {
        let mut c = if lenient {
            Controller::from_file_lenient(file).unwrap().0
        } else {
            Controller::from_file(file).unwrap()
        };
        c.set_inference(Inference::Mamdani);
        let out = dir.path().join("saved.fzz");
        c.save(&out).unwrap();
        let back = Controller::from_file(&out).unwrap();
        assert_eq!(back, c, "{file}");
    }
}
