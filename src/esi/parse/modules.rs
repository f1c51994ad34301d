//! `Descriptions/Modules/Module` and `Device/Slots` (ETG.2000 modular devices).

use super::{dict, parse_pdos, Ctx, Res, U32};
use crate::esi::warn::Oddity;
use crate::esi::*;
use roxmltree::Node;
use std::cell::Cell;
use std::collections::HashMap;
use std::sync::Arc;

/// Every `Module`. A module without a readable `Type ModuleIdent` cannot be named by a slot: it
/// is left out with a warning.
pub(super) fn parse_modules(cx: &Ctx, modules: Node) -> Res<Vec<Arc<Module>>> {
    let mut out = Vec::new();
    for m in cx.children(modules, "Module") {
        let ty = cx.require(m, "Type")?;
        let Some(ident) = cx.attr_opt_num(ty, "ModuleIdent", 0, U32) else {
            let oddity = Oddity::LeftOut {
                why: format!(
                    "module {:?} has no readable ModuleIdent: left out (no slot can name it)",
                    cx.text(ty)
                ),
            };
            cx.warn(ty, None, oddity);
            continue;
        };
        out.push(Arc::new(Module {
            type_name: cx.text(ty).to_string(),
            ident: ident as u32,
            class: ty.attribute("ModuleClass").map(str::to_string),
            names: cx.names(m),
            rx_pdos: parse_pdos(cx, m, "RxPdo")?,
            tx_pdos: parse_pdos(cx, m, "TxPdo")?,
            profile: dict::parse_profiles(cx, m)?,
        }));
    }
    Ok(out)
}

/// `Slots` of a device. The increments and instance counts lay out the process data: an
/// unreadable one is an error.
pub(super) fn parse_slots(cx: &Ctx, s: Node) -> Res<Slots> {
    let inc =
        |n: Node, name| -> Res<Option<u32>> { Ok(cx.attr_num(n, name, 0, U32)?.map(|v| v as u32)) };
    let slots = cx
        .children(s, "Slot")
        .map(|slot| -> Res<Slot> {
            let min = inc(slot, "MinInstances")?.unwrap_or(1);
            let max = inc(slot, "MaxInstances")?.unwrap_or(1).max(min);
            let modules = cx
                .children(slot, "ModuleIdent")
                .map(|m| -> Res<SlotModule> {
                    Ok(SlotModule {
                        ident: cx.elem_num(m, 0, U32)? as u32,
                        default: cx.attr_bool(m, "Default")?,
                    })
                })
                .collect::<Res<Vec<_>>>()?;
            Ok(Slot {
                name: cx.child_text(slot, "Name").unwrap_or_default(),
                min_instances: min,
                max_instances: max,
                slot_index_increment: inc(slot, "SlotIndexIncrement")?,
                slot_pdo_increment: inc(slot, "SlotPdoIncrement")?,
                modules,
                classes: cx
                    .children(slot, "ModuleClass")
                    .map(|c| cx.text(c).to_string())
                    .collect(),
            })
        })
        .collect::<Res<Vec<_>>>()?;
    Ok(Slots {
        slot_index_increment: inc(s, "SlotIndexIncrement")?.unwrap_or(0),
        slot_pdo_increment: inc(s, "SlotPdoIncrement")?.unwrap_or(0),
        slots,
    })
}

/// The file's modules by `ModuleIdent` and by `ModuleClass` (positions in file order).
#[derive(Default)]
pub(super) struct ModuleIndex {
    by_ident: HashMap<u32, Vec<usize>>,
    by_class: HashMap<String, Vec<usize>>,
    /// Module references handed out to devices so far (bounded, see [`slot_modules`]).
    refs: Cell<usize>,
}

impl ModuleIndex {
    pub(super) fn new(modules: &[Arc<Module>]) -> Self {
        let mut ix = ModuleIndex::default();
        for (i, m) in modules.iter().enumerate() {
            ix.by_ident.entry(m.ident).or_default().push(i);
            if let Some(c) = &m.class {
                ix.by_class.entry(c.clone()).or_default().push(i);
            }
        }
        ix
    }
}

/// Module references all devices of one file may hold: each is a pointer to a shared module,
/// so a file whose every device names every module by class stays within a few MiB.
const MAX_MODULE_REFERENCES: usize = 1 << 20;

/// The modules of the file that `slots` name (by ident or class), shared, in file order.
pub(super) fn slot_modules(
    cx: &Ctx,
    node: Node,
    slots: &Slots,
    file: &[Arc<Module>],
    ix: &ModuleIndex,
) -> Res<Vec<Arc<Module>>> {
    let mut at: Vec<usize> = Vec::new();
    for s in &slots.slots {
        for m in &s.modules {
            at.extend(ix.by_ident.get(&m.ident).into_iter().flatten());
        }
        for c in &s.classes {
            at.extend(ix.by_class.get(c).into_iter().flatten());
        }
        if ix.refs.get() + at.len() > MAX_MODULE_REFERENCES {
            return Err(cx.err(
                node,
                Problem::Unsupported(format!(
                    "more than {MAX_MODULE_REFERENCES} module references from the devices' slots"
                )),
            ));
        }
    }
    at.sort_unstable();
    at.dedup();
    ix.refs.set(ix.refs.get() + at.len());
    Ok(at.into_iter().map(|i| Arc::clone(&file[i])).collect())
}
