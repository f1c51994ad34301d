//! Machine files that pull ISG parameter-list files (`list = "…"`), and their errors.

use fieldprobe::params::MachineConfig;

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn example_machine_with_list_file_loads_the_list_values() {
    let p =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/machines/xy200-lists.toml");
    let cfg = MachineConfig::load(&p).unwrap();
    let x = cfg.axis("X").unwrap();
    assert_eq!(x.params.int("P-AXIS-00177"), -2_000_000);
    assert_eq!(x.params.int("P-AXIS-00178"), 2_000_000);
    assert_eq!(x.params.int("P-AXIS-00118"), 1);
}

#[test]
fn table_keys_override_the_list_and_list_errors_name_the_list_line() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "x.lis",
        "# X\nkenngr.swe_pos 3000000\nkenngr.swe_neg -3000000\n",
    );
    let m = write(
        dir.path(),
        "m.toml",
        "[[axis]]\nname = \"X\"\nlist = \"x.lis\"\nkenngr.swe_pos = 1000000\n",
    );
    let cfg = MachineConfig::load(&m).unwrap();
    assert_eq!(cfg.axis("X").unwrap().params.int("P-AXIS-00178"), 1_000_000);
    assert_eq!(
        cfg.axis("X").unwrap().params.int("P-AXIS-00177"),
        -3_000_000
    );

    write(
        dir.path(),
        "bad.lis",
        "kenngr.swe_neg -1000\nkenngr.swe_toleranz -5\n",
    );
    let m = write(
        dir.path(),
        "m2.toml",
        "[[axis]]\nname = \"X\"\nlist = \"bad.lis\"\n",
    );
    let e = MachineConfig::load(&m).unwrap_err().to_string();
    assert!(e.contains("bad.lis:2"), "{e}");
    assert!(e.contains("P-AXIS-00179"), "{e}");

    let m = write(
        dir.path(),
        "m3.toml",
        "[channel]\ncycle_time_us = 1000\n\n[[axis]]\nname = \"X\"\nlist = \"missing.lis\"\n",
    );
    let e = MachineConfig::load(&m).unwrap_err().to_string();
    assert!(e.contains("m3.toml:6") && e.contains("missing.lis"), "{e}");

    write(dir.path(), "chan.lis", "range_check_prog_soft_limits 1\n");
    let m = write(
        dir.path(),
        "m4.toml",
        "[channel]\nlist = \"chan.lis\"\n[[axis]]\nname = \"X\"\n",
    );
    let cfg = MachineConfig::load(&m).unwrap();
    assert_eq!(cfg.channel.int("P-CHAN-00498"), 1);
}

#[test]
fn probing_input_is_validated_per_drive_type() {
    use fieldprobe::machine::Machine;
    // Seed 004 §8.2.2 P-AXIS-00517 table: DRIVE on a CANopen / EtherCAT CiA 402 drive 1 … 2,
    // PLC_EXT_LATCH_CONTROL 1 … 255.
    let mut cfg = MachineConfig::default_machine();
    cfg.apply_set("Z.P-AXIS-00517=3").unwrap();
    let e = Machine::new(&cfg).unwrap_err().to_string();
    assert!(
        e.contains("P-AXIS-00517") && e.contains("1 … 2") && e.contains("axis Z"),
        "{e}"
    );
    cfg.apply_set("Z.P-AXIS-00516=PLC_EXT_LATCH_CONTROL")
        .unwrap();
    assert!(
        Machine::new(&cfg).is_ok(),
        "3 is fine for PLC_EXT_LATCH_CONTROL"
    );
    cfg.apply_set("Z.P-AXIS-00516=EXT_PROBE_WITH_DRIVE")
        .unwrap();
    assert!(Machine::new(&cfg).is_err(), "EXT_PROBE_WITH_DRIVE: 1 … 2");
}

#[test]
fn canopen_node_ids_come_from_the_node_key_or_the_axis_number() {
    let text =
        "[[axis]]\nname = \"X\"\n[[axis]]\nname = \"Y\"\nnode = 42\n[[axis]]\nname = \"Z\"\n";
    let mut cfg = MachineConfig::parse(text, "m.toml").unwrap();
    assert_eq!(cfg.axes[1].node, Some(42));
    assert_eq!(cfg.node_ids().unwrap(), vec![1, 42, 3]);
    cfg.apply_set("Z.node=7").unwrap();
    assert_eq!(cfg.node_ids().unwrap(), vec![1, 42, 7]);
    // Two axes on one id: named.
    cfg.apply_set("Z.node=1").unwrap();
    let e = cfg.node_ids().unwrap_err();
    assert!(e.contains("axes X and Z") && e.contains("node id 1"), "{e}");
    // Out of range, in the file (line named) and on the command line.
    for bad in ["0", "128", "\"5\"", "-1"] {
        let text = format!("[[axis]]\nname = \"X\"\nnode = {bad}\n");
        let e = MachineConfig::parse(&text, "m.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("m.toml") && e.contains(":3") && e.contains("1 … 127"),
            "{bad}: {e}"
        );
    }
    let e = cfg.apply_set("X.node=300").unwrap_err().to_string();
    assert!(e.contains("1 … 127"), "{e}");
}
