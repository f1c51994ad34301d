//! Device profiles as ESI files state them (ETG.2000 `Profile`), and the questions callers ask
//! of them: is this a CiA 402 drive, a Beckhoff MDP servo, what does 0x1000 say.
//!
//! A file states a profile in one of several places, all of which count:
//! * `Device/Profile/ProfileNo` (ETG.2000's own place: Ingenia, Bohign, the AX2000);
//! * `Device/Profile/ChannelInfo/ProfileNo` (one per channel; Inovance, LC10E, Eyou and the
//!   EJ7211-0011 write 402 only there);
//! * `ChannelInfo` with ProfileNo 5001 = ETG.5001 Modular Device Profile (MDP), whose `AddInfo`
//!   names the module profile: 513 "Servo interface", 511 "Stepper interface" / "DC motor
//!   interface", 742 servo, 703 / 733 motor, 704 "Positioning interface" (Beckhoff EJ72xx / EL72xx,
//!   EJ70xx);
//! * the `Profile` of the modules plugged into the device's slots (`Module/Profile/ProfileNo`,
//!   Eyou): the default modules for a device as the file describes it, the chosen ones for a
//!   resolved device ([`Device::resolve`](super::Device::resolve)).

use super::{Device, Dictionary, ObjectSubItem};

/// `Profile` (ETG.2000 ProfileType).
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// `ProfileNo` (402 = CiA 402 drive, 5001 = MDP), if given.
    pub profile_no: Option<u32>,
    /// `AddInfo` (profile-specific; the MDP module profile), if given.
    pub add_info: Option<u32>,
    /// `ChannelInfo` elements: one profile per channel.
    pub channels: Vec<ChannelInfo>,
    /// `Dictionary`, if given.
    pub dictionary: Option<Dictionary>,
}

/// `Profile/ChannelInfo`: the profile of one channel of the device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// `ProfileNo`.
    pub profile_no: u32,
    /// `AddInfo`, if given (for MDP 5001: the module profile, e.g. 513 servo interface).
    pub add_info: Option<u32>,
    /// `DisplayName` (first one), if given.
    pub display_name: Option<String>,
}

/// ETG.5001 Modular Device Profile.
pub const MDP: u32 = 5001;
/// CiA 402 drive profile.
pub const CIA402: u32 = 402;
/// MDP module profile "Servo interface" (`ChannelInfo` 5001 with `AddInfo` 513).
pub const MDP_SERVO_INTERFACE: u32 = 513;

impl Profile {
    /// `ProfileNo` and every `ChannelInfo` as (profile number, add info) pairs.
    fn numbers(&self) -> impl Iterator<Item = (u32, Option<u32>)> + '_ {
        self.profile_no
            .map(|p| (p, self.add_info))
            .into_iter()
            .chain(self.channels.iter().map(|c| (c.profile_no, c.add_info)))
    }
}

impl Device {
    /// The profiles that count for this device: its own, then those of its modules (the chosen
    /// ones once resolved, else the slots' default modules).
    fn profiles(&self) -> impl Iterator<Item = &Profile> + '_ {
        let modules: Vec<&Profile> = match &self.plugged {
            Some(plugged) => plugged.iter().filter_map(|p| p.profile.as_ref()).collect(),
            None => self
                .default_modules()
                .into_iter()
                .filter_map(|m| m.profile.as_ref())
                .collect(),
        };
        self.profile.iter().chain(modules)
    }

    /// Every (profile number, add info) the device declares: `Profile/ProfileNo`, each
    /// `ChannelInfo`, and its modules' profiles (see the module docs), in that order, without
    /// repeats.
    pub fn profile_infos(&self) -> Vec<(u32, Option<u32>)> {
        let mut out: Vec<(u32, Option<u32>)> = Vec::new();
        for n in self.profiles().flat_map(Profile::numbers) {
            if !out.contains(&n) {
                out.push(n);
            }
        }
        out
    }

    /// Every profile number the device declares (as [`Device::profile_infos`], without the
    /// add info), e.g. `[402]` or `[5001]`.
    pub fn profile_numbers(&self) -> Vec<u32> {
        let mut out: Vec<u32> = Vec::new();
        for (n, _) in self.profile_infos() {
            if !out.contains(&n) {
                out.push(n);
            }
        }
        out
    }

    /// The file says CiA 402 somewhere: device `ProfileNo`, a `ChannelInfo`, or a module's
    /// profile. This is what the file *states*; whether the dictionary has the objects of a
    /// CiA 402 axis (0x6040, 0x6041, …) is a separate question (an MDP servo such as the
    /// EJ7211-0010 has its drive objects at 0x6000 / 0x7000 + n·0x10 and states 5001 only).
    pub fn is_cia402(&self) -> bool {
        self.profile_numbers().contains(&CIA402)
    }

    /// The file states a Beckhoff Modular Device Profile servo channel: a `ChannelInfo` with
    /// ProfileNo 5001 and AddInfo 513 ("Servo interface", ETG.5001.1). Such a device is a servo
    /// drive, but its objects follow MDP (0x6000 / 0x7000 + n·0x10), not CiA 402's 0x6040….
    pub fn is_mdp_servo(&self) -> bool {
        self.profile_infos()
            .contains(&(MDP, Some(MDP_SERVO_INTERFACE)))
    }

    /// Every `ChannelInfo` of the device's profile and of its modules' profiles.
    pub fn channels(&self) -> Vec<&ChannelInfo> {
        self.profiles().flat_map(|p| p.channels.iter()).collect()
    }

    /// CoE object 0x1000 "Device type" as the file gives its default: `DefaultData` (hexBinary,
    /// little-endian; shorter data is zero-extended: 3 bytes `262546` → 0x00462526), else
    /// `DefaultValue` (a number: `#x00020192`), else sub-index 0's. `None` when the dictionary
    /// has no 0x1000, it has no default, or the data is longer than 4 bytes. The value is the
    /// file's, whether or not its low word says 402: callers that expect a drive warn, they do
    /// not refuse.
    pub fn device_type(&self) -> Option<u32> {
        let o = self.object(0x1000)?;
        let from_sub = |s: &ObjectSubItem| s.default_number();
        let v = if o.default_data.is_some() || o.values.default.is_some() {
            if o.default_data.as_ref().is_some_and(|d| d.len() > 4) {
                return None;
            }
            o.default_number()?
        } else {
            o.subitems.first().and_then(from_sub)?
        };
        u32::try_from(v).ok().or_else(|| {
            // a negative DefaultValue (read as 64-bit two's complement) of a 32-bit object
            i32::try_from(v as i64).ok().map(|v| v as u32)
        })
    }
}
