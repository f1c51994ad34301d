//! Parameter layer: registry against the seeds, ISG list text, machine TOML, `--set`.
//! Expected values come from the seeds (../shared/seeds) unless stated otherwise.

use crate::common::test_data;

use std::collections::BTreeSet;
use std::path::Path;

use fieldprobe::params::{
    find, id, parameters_markdown, parse_list, registry, suggest, DefaultValue, MachineConfig,
    Origin, ParamError, ParamSet, ParamType, ParamValue, Range, Scope,
};
use proptest::prelude::*;

fn seeds_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/seeds")
}

/// All P-AXIS-/P-CHAN-/P-MANU- IDs written in the seed texts.
fn seed_ids() -> BTreeSet<String> {
    let mut ids = BTreeSet::new();
    let dir = seeds_dir();
    let entries =
        std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()));
    for entry in entries {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("txt") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let bytes = text.as_bytes();
        for prefix in ["P-AXIS-", "P-CHAN-", "P-MANU-"] {
            let mut from = 0;
            while let Some(pos) = text[from..].find(prefix) {
                let start = from + pos;
                let digits = start + prefix.len();
                if bytes.len() >= digits + 5
                    && bytes[digits..digits + 5].iter().all(u8::is_ascii_digit)
                {
                    ids.insert(text[start..digits + 5].to_string());
                }
                from = digits;
            }
        }
    }
    ids
}

fn err_text<T: std::fmt::Debug>(r: Result<T, ParamError>) -> String {
    r.expect_err("expected an error").to_string()
}

// ---------------------------------------------------------------------------------------------
// Registry
// ---------------------------------------------------------------------------------------------

#[test]
fn every_seed_parameter_is_in_the_registry() {
    if !test_data::seeds_present("every_seed_parameter_is_in_the_registry") {
        return;
    }
    let ids = seed_ids();
    assert!(ids.len() >= 70, "only {} IDs found in the seeds", ids.len());
    let missing: Vec<_> = ids.iter().filter(|i| find(i).is_none()).collect();
    assert!(missing.is_empty(), "not in the registry: {missing:?}");
}

#[test]
fn every_default_lies_in_its_own_range() {
    for d in registry() {
        match (d.default, d.range) {
            (DefaultValue::Int(v), Range::Int { min, max }) => {
                assert!(
                    min <= v && v <= max,
                    "{}: default {v} not in {min}..={max}",
                    d.id
                );
                let (lo, hi) = d.ty.bounds().expect("integer type");
                assert!(lo <= min && max <= hi, "{}: range exceeds {}", d.id, d.ty);
                assert!(d.accepts_int(v), "{}", d.id);
            }
            (DefaultValue::Text(s), Range::Choice(words)) => {
                assert_eq!(d.ty, ParamType::Str, "{}", d.id);
                assert!(
                    s.is_empty() || words.contains(&s),
                    "{}: default '{s}' not a choice",
                    d.id
                );
            }
            (DefaultValue::Text(_), Range::AnyText) => assert_eq!(d.ty, ParamType::Str),
            other => panic!("{}: default and range disagree: {other:?}", d.id),
        }
        assert!(
            !d.range_text.is_empty() && !d.title.is_empty() && !d.dimension.is_empty(),
            "{}",
            d.id
        );
        assert!(
            d.source.starts_with("seed")
                || d.source
                    .starts_with("ISG online parameter docs (not in seeds)")
                || d.source.starts_with("project assumption"),
            "{}: source '{}'",
            d.id,
            d.source
        );
    }
}

#[test]
fn seed_defaults() {
    let axis = ParamSet::new(Scope::Axis);
    let chan = ParamSet::new(Scope::Channel);
    let manu = ParamSet::new(Scope::Manual);
    // seed 001 §4.3 / seed 000 §6.2
    for (id, v) in [
        ("P-AXIS-00014", 0),
        ("P-AXIS-00137", -1_000_000),
        ("P-AXIS-00138", 1_000_000),
        ("P-AXIS-00177", -100_000_000),
        ("P-AXIS-00178", 100_000_000),
        ("P-AXIS-00179", 1000),
        ("P-AXIS-00520", 0),
        ("P-AXIS-00521", 0),
        ("P-AXIS-00705", -1),
        // seed 004 §8.2.2 / §8.2.4
        ("P-AXIS-00060", 0),
        ("P-AXIS-00086", 50000),
        ("P-AXIS-00113", 0),
        ("P-AXIS-00118", 0),
        ("P-AXIS-00215", 16666),
        ("P-AXIS-00331", 0),
        ("P-AXIS-00332", 0),
        ("P-AXIS-00467", 0),
        ("P-AXIS-00517", 0),
        ("P-AXIS-00774", -1),
        ("P-AXIS-00775", 0),
        ("P-AXIS-00776", 0),
        ("P-AXIS-00777", -1),
        ("P-AXIS-00778", -1),
    ] {
        assert_eq!(axis.int(id), v, "{id}");
    }
    assert_eq!(axis.text("P-AXIS-00554"), "ERROR");
    assert_eq!(axis.text("P-AXIS-00516"), "", "seed 004: blank string");
    assert_eq!(axis.text("P-AXIS-00518"), "", "seed 004: blank string");
    for (id, v) in [
        ("P-CHAN-00057", 1),
        ("P-CHAN-00097", 0),
        ("P-CHAN-00176", 0),
        ("P-CHAN-00214", 0),
        ("P-CHAN-00266", 0),
        ("P-CHAN-00268", 0),
        ("P-CHAN-00296", 0),
        ("P-CHAN-00442", 0),
        ("P-CHAN-00489", 0),
        ("P-CHAN-00498", 0),
    ] {
        assert_eq!(chan.int(id), v, "{id}");
    }
    assert_eq!(manu.int("P-MANU-00014"), 0);
}

#[test]
fn seed_definitions() {
    // name path, type and range text exactly as the seeds write them
    let cases = [
        (
            "P-AXIS-00177",
            "kenngr.swe_neg",
            ParamType::Sgn32,
            "MIN(SGN32) < swe_neg < P-AXIS-00178",
        ),
        (
            "P-AXIS-00178",
            "kenngr.swe_pos",
            ParamType::Sgn32,
            "P-AXIS-00177 < swe_pos < MAX(SGN32)",
        ),
        (
            "P-AXIS-00179",
            "kenngr.swe_toleranz",
            ParamType::Uns32,
            "0 ≤ swe_toleranz ≤ MAX(UNS32)",
        ),
        (
            "P-AXIS-00137",
            "handbetrieb.offsetgrenze_neg",
            ParamType::Sgn32,
            "MIN(SGN32) ≤ offsetgrenze_neg ≤ 0",
        ),
        (
            "P-AXIS-00520",
            "lr_param.check_pos_command_limit",
            ParamType::Boolean,
            "0/1",
        ),
        (
            "P-AXIS-00215",
            "kenngr.vb_messen",
            ParamType::Uns32,
            "1 ≤ vb_messen ≤ P-AXIS-00212",
        ),
        (
            "P-AXIS-00777",
            "kenngr.measure.fixed_stop_detect.start_distance_per_mille",
            ParamType::Sgn16,
            "MIN(SGN16) < P-AXIS-00777 ≤ 1000",
        ),
        ("P-AXIS-00705", "kenngr.swe_check", ParamType::Sgn08, ""),
        (
            "P-CHAN-00498",
            "range_check_prog_soft_limits",
            ParamType::Boolean,
            "",
        ),
        ("P-CHAN-00057", "messtyp", ParamType::Uns16, ""),
        (
            "P-CHAN-00442",
            "suppress_workspace_monitoring_manual_mode",
            ParamType::Uns16,
            "0, 1, 2",
        ),
        (
            "P-MANU-00014",
            "move_limit_warning",
            ParamType::Boolean,
            "0/1",
        ),
        (
            "P-AXIS-00001",
            "getriebe[i].slope_profil.a_beschl",
            ParamType::Uns32,
            "",
        ),
        (
            "P-AXIS-00005",
            "getriebe[i].lslope_profil.a_grenz_stufe_1",
            ParamType::Uns32,
            "",
        ),
    ];
    for (id, path, ty, range_text) in cases {
        let d = find(id).unwrap();
        assert_eq!(d.path, path, "{id}");
        assert_eq!(d.ty, ty, "{id}");
        if !range_text.is_empty() {
            assert_eq!(d.range_text, range_text, "{id}");
        }
        assert_eq!(find(path).map(|d| d.id), Some(id), "{path}");
    }
    assert_eq!(
        find("P-AXIS-00177").unwrap().dimension,
        "T: 0.1µm, R: 0.0001°"
    );
    // parameters the seeds only mention: ISG definitions
    let a_emergency = find("P-AXIS-00003").unwrap();
    assert_eq!(a_emergency.path, "getriebe[i].dynamik.a_emergency");
    assert!(a_emergency
        .source
        .starts_with("ISG online parameter docs (not in seeds)"));
    assert_eq!(
        find("P-AXIS-00212").unwrap().path,
        "getriebe[i].dynamik.vb_max"
    );
    assert_eq!(
        find("P-AXIS-00018").unwrap().default,
        DefaultValue::Text("ACHSTYP_TRANSLATOR")
    );
    assert_eq!(find("P-AXIS-00015").unwrap().path, "kenngr.achs_mode");
}

#[test]
fn find_accepts_ids_any_case_and_index_zero() {
    assert_eq!(find("p-axis-00177").map(|d| d.path), Some("kenngr.swe_neg"));
    assert_eq!(
        find(" P-CHAN-00498 ").map(|d| d.path),
        Some("range_check_prog_soft_limits")
    );
    assert_eq!(
        find("getriebe[0].slope_profil.a_beschl").map(|d| d.id),
        Some("P-AXIS-00001")
    );
    assert_eq!(
        find("getriebe[i].slope_profil.a_beschl").map(|d| d.id),
        Some("P-AXIS-00001")
    );
    assert_eq!(
        find("lr_hw[0].mask_mess_1").map(|d| d.id),
        Some("P-AXIS-00106")
    );
    assert!(find("swe_neg").is_none(), "paths are exact");
    assert!(
        find("getriebe[1].slope_profil.a_beschl").is_none(),
        "one gear stage only"
    );
    assert!(find("").is_none());
    assert!(find("é").is_none());
    assert_eq!(
        suggest("kenngr.swe_nge").map(|d| d.id),
        Some("P-AXIS-00177")
    );
    assert_eq!(suggest("P-AXIS-0177").map(|d| d.id), Some("P-AXIS-00177"));
    assert_eq!(
        suggest("range_check_prog_soft_limit").map(|d| d.id),
        Some("P-CHAN-00498")
    );
    assert_eq!(
        suggest("hub_messtaster").map(|d| d.id),
        Some("P-AXIS-00086")
    );
    assert!(suggest("completely_unrelated_words").is_none());
}

#[test]
fn id_constants_match_registry() {
    assert_eq!(id::SWE_NEG, "P-AXIS-00177");
    assert_eq!(id::SWE_TOLERANZ, "P-AXIS-00179");
    assert_eq!(id::A_EMERGENCY, "P-AXIS-00003");
    assert_eq!(id::RANGE_CHECK_PROG_SOFT_LIMITS, "P-CHAN-00498");
    assert_eq!(id::MOVE_LIMIT_WARNING, "P-MANU-00014");
}

// ---------------------------------------------------------------------------------------------
// ParamSet
// ---------------------------------------------------------------------------------------------

#[test]
fn set_parses_per_type() {
    let o = Origin::new("t", 1);
    let mut s = ParamSet::new(Scope::Axis);
    for (raw, v) in [
        ("1", 1),
        ("0", 0),
        ("true", 1),
        ("FALSE", 0),
        ("True", 1),
        ("\"1\"", 1),
    ] {
        s.set("kenngr.messachse", raw, &o).unwrap();
        assert_eq!(s.int("P-AXIS-00118"), v, "{raw}");
    }
    s.set("kenngr.swe_toleranz", "0x10", &o).unwrap();
    assert_eq!(s.int(id::SWE_TOLERANZ), 16);
    s.set("P-AXIS-00177", " -5 ", &o).unwrap();
    assert_eq!(s.int("kenngr.swe_neg"), -5);
    s.set("kenngr.measure.signal", "plc_timestamp", &o).unwrap();
    assert_eq!(s.text(id::MEASURE_SIGNAL), "PLC_TIMESTAMP");
    s.set("kenngr.measure.edge", "", &o).unwrap();
    assert_eq!(
        s.text("P-AXIS-00518"),
        "",
        "blank = not defined (seed 004 §8.2.2)"
    );
    assert!(
        s.set("kenngr.swe_behaviour", "\"\"", &o).is_err(),
        "no blank for ERROR/ERROR_LR/WARNING"
    );
    s.set("kenngr.measure.edge", "'neg'", &o).unwrap();
    assert_eq!(s.text("P-AXIS-00518"), "NEG");
    assert!(s.is_set("kenngr.measure.edge") && s.is_set("P-AXIS-00518"));
    assert!(!s.is_set("P-AXIS-00179x"));
    assert_eq!(
        s.get(id::MEASURE_EDGE),
        Some(&ParamValue::Text("NEG".into()))
    );
    assert_eq!(s.origin_of(id::MEASURE_EDGE), Some(&o));
    assert_eq!(s.int(id::MEASURE_SIGNAL), 0, "text parameters read as 0");
    assert_eq!(
        s.text(id::SWE_NEG),
        "",
        "integer parameters read as empty text"
    );
    let ids: Vec<_> = s.iter_set().map(|(d, _)| d.id).collect();
    assert_eq!(
        ids,
        [
            "P-AXIS-00118",
            "P-AXIS-00177",
            "P-AXIS-00179",
            "P-AXIS-00516",
            "P-AXIS-00518"
        ]
    );
}

#[test]
fn set_rejects_bad_values_quoting_the_seed() {
    let o = Origin::new("x.lst", 4);
    let mut s = ParamSet::new(Scope::Axis);
    assert_eq!(
        err_text(s.set("kenngr.swe_toleranz", "-5", &o)),
        "x.lst:4: P-AXIS-00179 kenngr.swe_toleranz = -5 is out of range (seed: 0 ≤ swe_toleranz ≤ MAX(UNS32))"
    );
    assert_eq!(
        err_text(s.set("kenngr.swe_toleranz", "4294967296", &o)),
        "x.lst:4: P-AXIS-00179 kenngr.swe_toleranz = 4294967296 is out of range (seed: 0 ≤ swe_toleranz ≤ MAX(UNS32))"
    );
    assert_eq!(
        err_text(s.set("kenngr.swe_toleranz", "1.5", &o)),
        "x.lst:4: P-AXIS-00179 kenngr.swe_toleranz = 1.5 is not a valid UNS32 value (seed: 0 ≤ swe_toleranz ≤ MAX(UNS32))"
    );
    assert_eq!(
        err_text(s.set("kenngr.swe_behaviour", "LOUD", &o)),
        "x.lst:4: P-AXIS-00554 kenngr.swe_behaviour = LOUD is out of range (seed: ERROR, ERROR_LR, WARNING)"
    );
    assert!(err_text(s.set("kenngr.messachse", "2", &o)).contains("(seed: 0/1)"));
    assert!(err_text(s.set("kenngr.messachse", "yes", &o)).contains("is not a valid BOOLEAN value"));
    assert!(err_text(s.set("kenngr.swe_neg", "-2147483648", &o)).contains("MIN(SGN32) < swe_neg"));
    assert!(err_text(s.set("kenngr.swe_check", "2", &o)).contains("P-AXIS-00705"));
    assert!(err_text(s.set("messtyp", "3", &o)).contains("is a channel parameter"));
    assert!(err_text(s.set("messtyp", "3", &o)).contains("[channel]"));
    assert_eq!(s.iter_set().count(), 0, "nothing was set");
}

#[test]
fn set_int_is_range_checked() {
    let mut s = ParamSet::new(Scope::Channel);
    s.set_int(id::MESSTYP, 7).unwrap();
    assert_eq!(s.int("messtyp"), 7);
    assert_eq!(s.origin_of("messtyp"), Some(&Origin::api()));
    assert_eq!(
        err_text(s.set_int(id::MESSTYP, 8)),
        "<api>: P-CHAN-00057 messtyp = 8 is out of range (seed: 1*, 2*, 3, 4, 5, 6, 7* (measurement types; * also with independent axes))"
    );
    assert!(
        s.set_int(id::SWE_NEG, 1).is_err(),
        "axis parameter in a channel set"
    );
    let mut a = ParamSet::new(Scope::Axis);
    assert!(a.set_int(id::SWE_BEHAVIOUR, 1).is_err(), "text parameter");
}

#[test]
fn every_range_bound_is_accepted_and_exceeded_rejected() {
    let o = Origin::new("t", 1);
    for d in registry() {
        let mut s = ParamSet::new(d.scope);
        if let Range::Int { min, max } = d.range {
            for v in [min, max] {
                if d.accepts_int(v) {
                    s.set(d.id, &v.to_string(), &o).unwrap();
                }
            }
            assert!(
                s.set(d.id, &(min - 1).to_string(), &o).is_err(),
                "{} below",
                d.id
            );
            assert!(
                s.set(d.id, &(max + 1).to_string(), &o).is_err(),
                "{} above",
                d.id
            );
        }
    }
}

#[test]
fn cross_check_swe_neg_below_swe_pos() {
    let mut s = ParamSet::new(Scope::Axis);
    s.set_label("axis X");
    s.set("kenngr.swe_neg", "5", &Origin::new("l.lst", 2))
        .unwrap();
    s.set("kenngr.swe_pos", "4", &Origin::new("l.lst", 9))
        .unwrap();
    assert_eq!(
        err_text(s.check_cross(&Origin::new("l.lst", 0))),
        "l.lst:9 (axis X): P-AXIS-00177 kenngr.swe_neg = 5 must be < P-AXIS-00178 kenngr.swe_pos = 4"
    );
    s.set("kenngr.swe_pos", "6", &Origin::new("l.lst", 10))
        .unwrap();
    s.check_cross(&Origin::new("l.lst", 0)).unwrap();
}

#[test]
fn cross_check_dynamics_and_manual_limits() {
    let o = Origin::new("l", 1);
    let mut s = ParamSet::new(Scope::Axis);
    s.set("getriebe[i].slope_profil.a_beschl", "2000", &o)
        .unwrap();
    let e = err_text(s.check_cross(&o));
    assert!(
        e.contains("P-AXIS-00001")
            && e.contains("must be ≤ P-AXIS-00008 getriebe[i].dynamik.a_max = 1000"),
        "{e}"
    );
    s.set("getriebe[i].dynamik.a_max", "3000", &o).unwrap();
    s.check_cross(&o).unwrap();
    s.set("getriebe[i].dynamik.a_emergency", "6001", &o)
        .unwrap();
    assert!(err_text(s.check_cross(&o)).contains("2 × P-AXIS-00008"));
    s.set("getriebe[i].dynamik.a_emergency", "0", &o).unwrap();
    s.set("kenngr.vb_messen", "300000", &o).unwrap();
    assert!(err_text(s.check_cross(&o)).contains("P-AXIS-00212"));
    s.set("kenngr.vb_messen", "200000", &o).unwrap();
    s.set("handbetrieb.acs_limit_pos", "100000001", &o).unwrap();
    assert!(err_text(s.check_cross(&o)).contains("P-AXIS-00493"));
    s.set("handbetrieb.acs_limit_pos", "0", &o).unwrap();
    s.check_cross(&o).unwrap();
}

// ---------------------------------------------------------------------------------------------
// ISG list text
// ---------------------------------------------------------------------------------------------

#[test]
fn seed_004_parameterisation_example() {
    // seed 004 §3 "Parameterisation example" (the PDF text lost the underscores of
    // hub_messtaster and vb_messen)
    let text = "kenngr.messachse\t1\nkenngr.hub_messtaster\t100000\nkenngr.vb_messen\t10000\n\
                kenngr.probing_offset\t0\nkenngr.measure.signal\tPLC\nkenngr.measure.input\t1\n\
                kenngr.measure.edge\tPOS\n";
    let s = parse_list(text, "meas.lst", Scope::Axis).unwrap();
    assert_eq!(s.int("P-AXIS-00118"), 1);
    assert_eq!(s.int("P-AXIS-00086"), 100000);
    assert_eq!(s.int("P-AXIS-00215"), 10000);
    assert_eq!(s.int("P-AXIS-00467"), 0);
    assert_eq!(s.text("P-AXIS-00516"), "PLC");
    assert_eq!(s.int("P-AXIS-00517"), 1);
    assert_eq!(s.text("P-AXIS-00518"), "POS");
    assert_eq!(s.iter_set().count(), 7);
}

#[test]
fn seed_004_sercos_and_external_latch_examples() {
    // seed 004 §6.1 example (SERCOS, real-time bit 1)
    let s = parse_list(
        "kenngr.hub_messtaster 2000\nkenngr.vb_messen 2000\nkenngr.messachse 1\n\
         kenngr.measure.signal DRIVE\nkenngr.echtzeit_bit_nr 1\n",
        "sercos.lst",
        Scope::Axis,
    )
    .unwrap();
    assert_eq!(
        (
            s.int("P-AXIS-00086"),
            s.int("P-AXIS-00215"),
            s.int("P-AXIS-00060")
        ),
        (2000, 2000, 1)
    );
    assert_eq!(s.text("P-AXIS-00516"), "DRIVE");
    // seed 004 §7.4 (external measuring hardware)
    let s = parse_list(
        "kenngr.measure.signal PLC_EXT_LATCH_CONTROL\nkenngr.measure.input 4\nkenngr.measure.edge NEG\n",
        "ext.lst",
        Scope::Axis,
    )
    .unwrap();
    assert_eq!(
        (
            s.text(id::MEASURE_SIGNAL),
            s.int(id::MEASURE_INPUT),
            s.text(id::MEASURE_EDGE)
        ),
        ("PLC_EXT_LATCH_CONTROL", 4, "NEG")
    );
}

#[test]
fn seed_channel_examples() {
    // seed 004 §8.2.1 and §7.3, seed 000 §6.2 parameterisation examples
    let s = parse_list(
        "meas_error_no_signal 1\nmeas_deceleration_mode 1\nmeas_fixed_stop_no_error 1\n\
         meas_use_std_dynamic 1\nmeas_soft_limit_move_path 1\nmesstyp 7\n",
        "chan.lst",
        Scope::Channel,
    )
    .unwrap();
    for i in [
        "P-CHAN-00176",
        "P-CHAN-00214",
        "P-CHAN-00266",
        "P-CHAN-00296",
        "P-CHAN-00268",
    ] {
        assert_eq!(s.int(i), 1, "{i}");
    }
    assert_eq!(s.int("P-CHAN-00057"), 7);
}

#[test]
fn list_syntax_comments_and_forms() {
    let text = "# axis list\n; semicolon comment\n( bracket comment )\n\n\
                kenngr.swe_neg = -2000000   # trailing\n\
                P-AXIS-00178   2000000 ; trailing\n\
                kenngr.measure.signal \"plc\" ( trailing )\n\
                kenngr.swe_toleranz=0x3E8\n";
    let s = parse_list(text, "a.lst", Scope::Axis).unwrap();
    assert_eq!(s.int(id::SWE_NEG), -2_000_000);
    assert_eq!(s.int(id::SWE_POS), 2_000_000);
    assert_eq!(s.text(id::MEASURE_SIGNAL), "PLC");
    assert_eq!(s.int(id::SWE_TOLERANZ), 1000);
    assert_eq!(s.origin_of(id::SWE_POS), Some(&Origin::new("a.lst", 6)));
}

#[test]
fn list_errors_name_file_line_and_key() {
    assert_eq!(
        err_text(parse_list("kenngr.messachse 1\nkenngr.hub messtaster 100000\n", "seed.lst", Scope::Axis)),
        "seed.lst:2: unknown parameter 'kenngr.hub'; did you mean 'kenngr.hub_messtaster' (P-AXIS-00086)?"
    );
    assert_eq!(
        err_text(parse_list("\n\nkenngr.swe_nge -5\n", "a.lst", Scope::Axis)),
        "a.lst:3: unknown parameter 'kenngr.swe_nge'; did you mean 'kenngr.swe_neg' (P-AXIS-00177)?"
    );
    assert_eq!(
        err_text(parse_list("# c\nkenngr.swe_toleranz -5\n", "a.lst", Scope::Axis)),
        "a.lst:2: P-AXIS-00179 kenngr.swe_toleranz = -5 is out of range (seed: 0 ≤ swe_toleranz ≤ MAX(UNS32))"
    );
    assert_eq!(
        err_text(parse_list("kenngr.swe_neg\n", "a.lst", Scope::Axis)),
        "a.lst:1: 'kenngr.swe_neg' has no value; expected 'kenngr.swe_neg <value>'"
    );
    let e = err_text(parse_list(
        "range_check_prog_soft_limits 1\n",
        "a.lst",
        Scope::Axis,
    ));
    assert!(
        e.starts_with("a.lst:1: P-CHAN-00498 range_check_prog_soft_limits is a channel parameter"),
        "{e}"
    );
    // cross check at the end: line of the last assignment involved
    assert_eq!(
        err_text(parse_list(
            "kenngr.swe_pos 4\n# x\nkenngr.swe_neg 5\nkenngr.messachse 1\n",
            "a.lst",
            Scope::Axis
        )),
        "a.lst:3: P-AXIS-00177 kenngr.swe_neg = 5 must be < P-AXIS-00178 kenngr.swe_pos = 4"
    );
}

// ---------------------------------------------------------------------------------------------
// Machine TOML
// ---------------------------------------------------------------------------------------------

const MACHINE: &str = r#"[channel]
cycle_time_us = 2000
"P-CHAN-00498" = 1
meas_soft_limit_move_path = true

[manual]
move_limit_warning = true

[[axis]]
name = "X"
drive = "cia402-generic"
referenced = true
kenngr.swe_neg = -2000000
"P-AXIS-00178" = 2000000
"getriebe[i].slope_profil.a_beschl" = 2000
"getriebe[i]".dynamik.a_max = 3000
kenngr.measure = { signal = "plc", edge = "NEG" }

[[axis]]
name = "Z"
referenced = false
kenngr.messachse = 1

[axis.handbetrieb]
offsetgrenze_neg = -5
"#;

#[test]
fn machine_file_parses() {
    let m = MachineConfig::parse(MACHINE, "machine.toml").unwrap();
    assert_eq!(m.source, "machine.toml");
    assert_eq!(m.cycle_time_us, 2000);
    assert_eq!(m.channel.int("range_check_prog_soft_limits"), 1);
    assert_eq!(m.channel.int("P-CHAN-00268"), 1);
    assert_eq!(m.manual.int("P-MANU-00014"), 1);
    assert_eq!(m.axes.len(), 2);
    let x = m.axis("X").unwrap();
    assert_eq!((x.drive.as_str(), x.referenced), ("cia402-generic", true));
    assert_eq!(x.params.int(id::SWE_NEG), -2_000_000);
    assert_eq!(x.params.int(id::SWE_POS), 2_000_000);
    assert_eq!(x.params.int(id::A_BESCHL), 2000);
    assert_eq!(x.params.int(id::A_MAX), 3000);
    assert_eq!(x.params.text(id::MEASURE_SIGNAL), "PLC");
    assert_eq!(x.params.text(id::MEASURE_EDGE), "NEG");
    assert_eq!(
        x.params.origin_of(id::SWE_POS),
        Some(&Origin::new("machine.toml", 14))
    );
    assert_eq!(x.params.label(), Some("axis X"));
    let z = m.axis("Z").unwrap();
    assert_eq!((z.drive.as_str(), z.referenced), ("cia402-generic", false));
    assert_eq!(z.params.int(id::MESSACHSE), 1);
    assert_eq!(z.params.int(id::OFFSETGRENZE_NEG), -5);
    assert_eq!(
        z.params.origin_of(id::OFFSETGRENZE_NEG),
        Some(&Origin::new("machine.toml", 25))
    );
    assert!(m.axis("Y").is_none());
}

#[test]
fn machine_defaults() {
    let m = MachineConfig::parse("[[axis]]\nname = \"X\"\n", "m.toml").unwrap();
    assert_eq!(m.cycle_time_us, 1000);
    let x = m.axis("X").unwrap();
    assert_eq!((x.drive.as_str(), x.referenced), ("cia402-generic", true));
    assert_eq!(x.params.iter_set().count(), 0);
    assert_eq!(x.params.int(id::SWE_POS), 100_000_000);
}

#[test]
fn machine_unknown_key_suggests() {
    // (Line 4 is a comment: the same parameter by ID and by name is refused since issue 15.)
    let text = "[channel]\ncycle_time_us = 1000\n\"P-CHAN-00498\" = 1\n# range_check_prog_soft_limits\n\n\
                [manual]\nmove_limit_warning = true\n\n[[axis]]\nname = \"X\"\ndrive = \"cia402-generic\"\n\
                kenngr.swe_nge = -2000000\n";
    assert_eq!(
        err_text(MachineConfig::parse(text, "machine.toml")),
        "machine.toml:12: unknown parameter 'kenngr.swe_nge'; did you mean 'kenngr.swe_neg' (P-AXIS-00177)?"
    );
    let e = err_text(MachineConfig::parse(
        "[[axis]]\nname = \"X\"\nrefrenced = true\n",
        "m.toml",
    ));
    assert_eq!(
        e,
        "m.toml:3: unknown parameter 'refrenced'; did you mean 'referenced'?"
    );
}

#[test]
fn machine_out_of_range_names_line_and_seed_text() {
    let text =
        "[[axis]]\nname = \"X\"\n\n# tolerance\n\nkenngr.swe_neg = -5\nkenngr.swe_toleranz = -5\n";
    assert_eq!(
        err_text(MachineConfig::parse(text, "machine.toml")),
        "machine.toml:7: P-AXIS-00179 kenngr.swe_toleranz = -5 is out of range (seed: 0 ≤ swe_toleranz ≤ MAX(UNS32))"
    );
    let e = err_text(MachineConfig::parse(
        "[[axis]]\nname = \"X\"\nkenngr.swe_toleranz = 1000.0\n",
        "m.toml",
    ));
    assert!(
        e.starts_with(
            "m.toml:3: P-AXIS-00179 kenngr.swe_toleranz = 1000.0 is not a valid UNS32 value"
        ),
        "{e}"
    );
    let e = err_text(MachineConfig::parse(
        "[[axis]]\nname = \"X\"\nkenngr.messachse = [1]\n",
        "m.toml",
    ));
    assert!(
        e.starts_with("m.toml:3: kenngr.messachse: expected an integer, boolean or string"),
        "{e}"
    );
}

#[test]
fn machine_cross_check() {
    let text = "[[axis]]\nkenngr.swe_pos = 4\nkenngr.swe_neg = 5\nname = \"X\"\n";
    assert_eq!(
        err_text(MachineConfig::parse(text, "machine.toml")),
        "machine.toml:3 (axis X): P-AXIS-00177 kenngr.swe_neg = 5 must be < P-AXIS-00178 kenngr.swe_pos = 4"
    );
}

#[test]
fn machine_toml_syntax_errors_have_lines() {
    for (text, line) in [
        ("[channel]\nmesstyp = 1\n\nkenngr.swe_neg = \n", 4),
        ("[[axis]]\nname = \"X\"\nname = \"Y\"\n", 3),
        ("\n\n[channel\n", 3),
        ("[[axis]]\nname = \"X\n", 2),
    ] {
        let e = err_text(MachineConfig::parse(text, "m.toml"));
        assert!(
            e.starts_with(&format!("m.toml:{line}: invalid TOML: ")),
            "{text:?} -> {e}"
        );
    }
}

#[test]
fn machine_structure_errors() {
    let cases = [
        ("[foo]\nx = 1\n", "m.toml:1: unknown table [foo]; allowed tables are [channel], [manual], [[axis]], [[terminal]], [tool.<D>], [zero_offset.G54…G59] and [can]"),
        ("cycle_time_us = 1000\n", "m.toml:1: 'cycle_time_us' is outside any table; allowed tables are [channel], [manual], [[axis]], [[terminal]], [tool.<D>], [zero_offset.G54…G59] and [can]; cycle_time_us belongs in [channel]"),
        // Issue 16: [can] bitrate.
        ("bitrate = 500000\n", "m.toml:1: 'bitrate' is outside any table; allowed tables are [channel], [manual], [[axis]], [[terminal]], [tool.<D>], [zero_offset.G54…G59] and [can]; bitrate belongs in [can]"),
        ("[can]\nbitrat = 500000\n[[axis]]\nname = \"X\"\n", "m.toml:2: unknown key 'bitrat' in [can] (did you mean bitrate?); allowed: bitrate"),
        ("[can]\nbitrate = 1000001\n[[axis]]\nname = \"X\"\n", "m.toml:2: bitrate = 1000001: not a CAN bit rate of CiA 301; allowed: 10k, 20k, 50k, 125k, 250k, 500k, 800k, 1M (bit/s, e.g. bitrate = 500000 or \"500k\" in [can])"),
        ("[can]\nbitrate = true\n[[axis]]\nname = \"X\"\n", "m.toml:2: bitrate = (not a number): not a CAN bit rate of CiA 301; allowed: 10k, 20k, 50k, 125k, 250k, 500k, 800k, 1M (bit/s, e.g. bitrate = 500000 or \"500k\" in [can])"),
        ("can = 1\n[[axis]]\nname = \"X\"\n", "m.toml:1: 'can' must be a table: write [can] bitrate = 500000"),
        ("[axis]\nname = \"X\"\n", "m.toml:1: 'axis' must be an array of tables: write [[axis]] once per axis"),
        ("[channel]\nmesstyp = 1\n", "m.toml: no [[axis]] table; a machine needs at least one axis (name = \"X\")"),
        ("[[axis]]\ndrive = \"x\"\n", "m.toml:1: [[axis]] without a name; expected e.g. name = \"X\""),
        ("[[axis]]\nname = \"Q\"\n", "m.toml:2: invalid axis name 'Q'; expected one of X Y Z A B C U V W, optionally followed by digits (e.g. \"X2\")"),
        ("[[axis]]\nname = \"X\"\n[[axis]]\nname = \"X\"\n", "m.toml:4: duplicate axis name 'X' (first defined at line 2)"),
        ("[[axis]]\nname = 1\n", "m.toml:2: 'name' must be a string: an axis name such as \"X\""),
        ("[[axis]]\nname = \"X\"\nreferenced = 1\n", "m.toml:3: 'referenced' must be true or false"),
        ("[[axis]]\nname = \"X\"\ndrive = \"../x\"\n", "m.toml:3: invalid drive '../x'; expected the name of a drives/<name>.toml definition (letters, digits, '-', '_') or the path of a drive file ending in .toml"),
        ("[channel]\ncycle_time_us = 50\n[[axis]]\nname = \"X\"\n", "m.toml:2: cycle_time_us = 50: cycle_time_us must be an integer number of µs, 100 ..= 100000"),
    ];
    for (text, expected) in cases {
        assert_eq!(
            err_text(MachineConfig::parse(text, "m.toml")),
            expected,
            "{text:?}"
        );
    }
    // [can] bitrate: every CiA 301 rate, as bit/s or with k / M; the default 1 Mbit/s.
    let axis = "[[axis]]\nname = \"X\"\n";
    assert_eq!(
        MachineConfig::parse(axis, "m.toml").unwrap().can_bitrate,
        1_000_000
    );
    for (v, bps) in [
        ("10000", 10_000),
        ("\"20k\"", 20_000),
        ("\"50K\"", 50_000),
        ("125000", 125_000),
        ("\"250k\"", 250_000),
        ("500000", 500_000),
        ("\"800k\"", 800_000),
        ("\"1M\"", 1_000_000),
    ] {
        let cfg = MachineConfig::parse(&format!("[can]\nbitrate = {v}\n{axis}"), "m.toml").unwrap();
        assert_eq!(cfg.can_bitrate, bps, "{v}");
    }
    let mut cfg = MachineConfig::parse(axis, "m.toml").unwrap();
    cfg.apply_set("can.bitrate=125k").unwrap();
    assert_eq!(cfg.can_bitrate, 125_000);
    let e = cfg.apply_set("can.bitrate=100k").unwrap_err().to_string();
    assert!(
        e.starts_with("--set: bitrate = 100k: not a CAN bit rate"),
        "{e}"
    );
    assert_eq!(cfg.can_bitrate, 125_000, "unchanged on error");
    let e = err_text(MachineConfig::parse(
        "[channel]\n\"P-AXIS-00178\" = 1\n[[axis]]\nname = \"X\"\n",
        "m.toml",
    ));
    assert_eq!(e, "m.toml:2: P-AXIS-00178 kenngr.swe_pos is an axis parameter and cannot be set in [channel] (channel parameter list); set it in an [[axis]] table (axis parameter list)");
    let e = err_text(MachineConfig::parse(
        "[[axis]]\nname = \"X\"\nmove_limit_warning = 1\n",
        "m.toml",
    ));
    assert!(
        e.starts_with("m.toml:3: P-MANU-00014 move_limit_warning is a manual-mode parameter")
            && e.contains("[manual]"),
        "{e}"
    );
}

#[test]
fn machine_load_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.toml");
    let e = err_text(MachineConfig::load(&missing));
    assert!(
        e.starts_with(&format!("{}: cannot read file: ", missing.display())),
        "{e}"
    );
    let file = dir.path().join("m.toml");
    std::fs::write(&file, "[[axis]]\nname = \"X\"\nkenngr.swe_toleranz = -1\n").unwrap();
    let e = err_text(MachineConfig::load(&file));
    assert!(
        e.starts_with(&format!("{}:3: P-AXIS-00179", file.display())),
        "{e}"
    );
    std::fs::write(&file, MACHINE).unwrap();
    assert_eq!(MachineConfig::load(&file).unwrap().axes.len(), 2);
}

#[test]
fn default_machine_per_design() {
    let m = MachineConfig::default_machine();
    assert_eq!(m.axis_list(), "X, Y, Z");
    assert_eq!(m.cycle_time_us, 1000);
    for a in &m.axes {
        assert!(a.referenced);
        assert_eq!(a.drive, "cia402-generic");
        assert_eq!(a.params.int("kenngr.messachse"), 1);
        assert_eq!(a.params.text("kenngr.measure.signal"), "DRIVE");
        assert_eq!(a.params.int("kenngr.measure.input"), 1);
        assert_eq!(a.params.text("kenngr.measure.edge"), "POS");
        assert_eq!(a.params.int(id::SWE_NEG), -100_000_000);
        a.params.check_cross(&Origin::new("<default>", 0)).unwrap();
    }
}

// ---------------------------------------------------------------------------------------------
// --set
// ---------------------------------------------------------------------------------------------

#[test]
fn set_variants() {
    let mut m = MachineConfig::default_machine();
    m.apply_set("P-CHAN-00498=1").unwrap();
    assert_eq!(m.channel.int(id::RANGE_CHECK_PROG_SOFT_LIMITS), 1);
    m.apply_set("meas_soft_limit_move_path=1").unwrap();
    m.apply_set("range_check_prog_soft_limits=0").unwrap();
    assert_eq!(m.channel.int(id::RANGE_CHECK_PROG_SOFT_LIMITS), 0);
    m.apply_set("X.P-AXIS-00178=2000000").unwrap();
    assert_eq!(m.axis("X").unwrap().params.int(id::SWE_POS), 2_000_000);
    assert_eq!(m.axis("Y").unwrap().params.int(id::SWE_POS), 100_000_000);
    m.apply_set("Z.kenngr.measure.signal=PLC").unwrap();
    assert_eq!(m.axis("Z").unwrap().params.text(id::MEASURE_SIGNAL), "PLC");
    m.apply_set("P-MANU-00014=1").unwrap();
    assert_eq!(m.manual.int(id::MOVE_LIMIT_WARNING), 1);
    m.apply_set(" Y.getriebe[0].dynamik.a_max = 5000 ").unwrap();
    assert_eq!(m.axis("Y").unwrap().params.int(id::A_MAX), 5000);
    m.apply_set("cycle_time_us=500").unwrap();
    assert_eq!(m.cycle_time_us, 500);
    m.apply_set("X.referenced=false").unwrap();
    assert!(!m.axis("X").unwrap().referenced);
    m.apply_set("X.drive=cia402-other").unwrap();
    assert_eq!(m.axis("X").unwrap().drive, "cia402-other");
    assert_eq!(
        m.axis("Z").unwrap().params.origin_of(id::MEASURE_SIGNAL),
        Some(&Origin::new("--set", 0))
    );
}

#[test]
fn set_errors() {
    let mut m = MachineConfig::default_machine();
    assert_eq!(
        err_text(m.apply_set("P-AXIS-00178=2000000")),
        "--set: P-AXIS-00178 kenngr.swe_pos is an axis parameter; prefix it with the axis name, e.g. 'X.P-AXIS-00178=2000000' (axes: X, Y, Z)"
    );
    assert_eq!(
        err_text(m.apply_set("Q.P-AXIS-00178=1")),
        "--set: unknown axis 'Q' in 'Q.P-AXIS-00178=1'; the machine has axes X, Y, Z"
    );
    assert_eq!(
        err_text(m.apply_set("X.kenngr.swe_nge=1")),
        "--set: unknown parameter 'kenngr.swe_nge'; did you mean 'kenngr.swe_neg' (P-AXIS-00177)?"
    );
    assert_eq!(
        err_text(m.apply_set("messtyp")),
        "--set: 'messtyp': expected KEY=VALUE, e.g. 'X.P-AXIS-00178=2000000'"
    );
    assert_eq!(
        err_text(m.apply_set("=1")),
        "--set: '=1': expected KEY=VALUE, e.g. 'X.P-AXIS-00178=2000000'"
    );
    assert_eq!(
        err_text(m.apply_set("messtyp=9")),
        "--set: P-CHAN-00057 messtyp = 9 is out of range (seed: 1*, 2*, 3, 4, 5, 6, 7* (measurement types; * also with independent axes))"
    );
    assert!(err_text(m.apply_set("X.name=Y")).contains("cannot be changed"));
    assert!(err_text(m.apply_set("cycle_time_us=1")).contains("100 ..= 100000"));
    // the cross check is re-run and a failed --set changes nothing
    assert_eq!(
        err_text(m.apply_set("X.P-AXIS-00178=-200000000")),
        "--set (axis X): P-AXIS-00177 kenngr.swe_neg = -100000000 must be < P-AXIS-00178 kenngr.swe_pos = -200000000"
    );
    assert_eq!(m.axis("X").unwrap().params.int(id::SWE_POS), 100_000_000);
    assert!(!m.axis("X").unwrap().params.is_set(id::SWE_POS));
    assert_eq!(m, MachineConfig::default_machine());
}

#[test]
fn set_cross_checks_run_after_all_sets_in_any_order() {
    // Seed 001 §4.3: P-AXIS-00177 < P-AXIS-00178. Moving X's range from the default ±10000 mm
    // to [12000, 15000] mm needs both: either assignment alone leaves neg ≥ pos.
    let neg = "X.P-AXIS-00177=120000000";
    let pos = "X.P-AXIS-00178=150000000";
    let mut a = MachineConfig::default_machine();
    a.apply_sets(&[neg, pos]).unwrap();
    let mut b = MachineConfig::default_machine();
    b.apply_sets(&[pos, neg]).unwrap();
    for m in [&a, &b] {
        let x = &m.axis("X").unwrap().params;
        assert_eq!(
            (x.int(id::SWE_NEG), x.int(id::SWE_POS)),
            (120_000_000, 150_000_000)
        );
    }
    assert_eq!(a, b, "the same machine in either order");
    // Seed 004 §8.2.2: 1 ≤ vb_messen ≤ P-AXIS-00212; raising both, in either order.
    let vb = "Z.P-AXIS-00215=900000";
    let vmax = "Z.P-AXIS-00212=1000000";
    for sets in [[vb, vmax], [vmax, vb]] {
        let mut m = MachineConfig::default_machine();
        m.apply_sets(&sets).unwrap();
        assert_eq!(m.axis("Z").unwrap().params.int(id::VB_MESSEN), 900_000);
    }
    // A result that breaks the rule is refused in either order with the same message, naming
    // both parameters, and changes nothing.
    let bad = "X.P-AXIS-00178=110000000";
    let expected = "--set (axis X): P-AXIS-00177 kenngr.swe_neg = 120000000 must be < P-AXIS-00178 kenngr.swe_pos = 110000000";
    for sets in [[neg, bad], [bad, neg]] {
        let mut m = MachineConfig::default_machine();
        assert_eq!(err_text(m.apply_sets(&sets)), expected, "{sets:?}");
        assert_eq!(m, MachineConfig::default_machine(), "{sets:?}");
    }
    // An assignment outside its own data range is still refused where it stands.
    let mut m = MachineConfig::default_machine();
    assert!(err_text(m.apply_sets(&[neg, "X.P-AXIS-00179=-5", pos])).contains("P-AXIS-00179"));
    assert_eq!(m, MachineConfig::default_machine());
}

// ---------------------------------------------------------------------------------------------
// Generated documentation
// ---------------------------------------------------------------------------------------------

#[test]
fn parameters_doc_is_up_to_date() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/parameters.md");
    let expected = parameters_markdown();
    if std::env::var_os("FIELDPROBE_BLESS").is_some() {
        std::fs::write(&path, &expected).unwrap();
    }
    let actual = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        actual == expected,
        "docs/parameters.md is out of date; regenerate with FIELDPROBE_BLESS=1 cargo test --test it params::"
    );
    for d in registry() {
        assert!(
            actual.contains(&format!("| {} | `{}` |", d.id, d.path)),
            "{}",
            d.id
        );
    }
}

// ---------------------------------------------------------------------------------------------
// No panics on any input
// ---------------------------------------------------------------------------------------------

fn key_strategy() -> impl Strategy<Value = String> {
    let known: Vec<String> = registry()
        .iter()
        .flat_map(|d| [d.id.to_string(), d.path.to_string()])
        .collect();
    prop_oneof![
        prop::sample::select(known),
        prop::sample::select(vec![
            "name".to_string(),
            "drive".to_string(),
            "referenced".to_string(),
            "cycle_time_us".to_string(),
            "\"getriebe[i]\".dynamik.a_max".to_string(),
            "kenngr".to_string(),
        ]),
        "[a-z_.\\[\\]0-9-]{0,24}",
    ]
}

fn value_strategy() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<i64>().prop_map(|v| v.to_string()),
        (-5i64..5).prop_map(|v| v.to_string()),
        prop::sample::select(vec![
            "true",
            "false",
            "\"PLC\"",
            "\"X\"",
            "0x7fffffff",
            "-0x80000000",
            "1.5",
            "[1, 2]",
            "{ a = 1 }",
            "\"\"",
            "99999999999999999999999",
            "\"DRIVE\"",
            "nan",
        ])
        .prop_map(str::to_string),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn parse_list_never_panics(text in "\\PC{0,200}", scope in prop::sample::select(vec![Scope::Axis, Scope::Channel, Scope::Manual])) {
        let _ = parse_list(&text, "fuzz.lst", scope);
    }

    #[test]
    fn machine_parse_never_panics(text in "\\PC{0,200}") {
        let _ = MachineConfig::parse(&text, "fuzz.toml");
    }

    #[test]
    fn structured_list_never_panics(lines in prop::collection::vec((key_strategy(), value_strategy(), prop::sample::select(vec![" ", "\t", " = ", "="])), 0..12)) {
        let text: String = lines.iter().map(|(k, v, sep)| format!("{k}{sep}{v}\n")).collect();
        for scope in [Scope::Axis, Scope::Channel, Scope::Manual] {
            if let Err(e) = parse_list(&text, "fuzz.lst", scope) {
                prop_assert!(e.to_string().starts_with("fuzz.lst"), "{}", e);
            }
        }
    }

    #[test]
    fn structured_toml_never_panics(
        sections in prop::collection::vec(
            (prop::sample::select(vec!["[channel]", "[manual]", "[[axis]]", "[axis.kenngr]", "[x]", ""]),
             prop::collection::vec((key_strategy(), value_strategy()), 0..6)),
            0..5)
    ) {
        let mut text = String::new();
        for (header, entries) in &sections {
            text.push_str(header);
            text.push('\n');
            for (k, v) in entries {
                let k = if k.contains('[') && !k.starts_with('"') { format!("\"{k}\"") } else { k.clone() };
                text.push_str(&format!("{k} = {v}\n"));
            }
        }
        if let Err(e) = MachineConfig::parse(&text, "fuzz.toml") {
            prop_assert!(e.to_string().starts_with("fuzz.toml"), "{}", e);
        }
    }

    #[test]
    fn apply_set_never_panics(assignment in "\\PC{0,60}", key in key_strategy(), value in value_strategy(), axis in prop::sample::select(vec!["", "X.", "Z.", "Q.", "x."])) {
        let mut m = MachineConfig::default_machine();
        let _ = m.apply_set(&assignment);
        let before = m.clone();
        if m.apply_set(&format!("{axis}{key}={value}")).is_err() {
            prop_assert_eq!(m, before);
        }
    }
}
