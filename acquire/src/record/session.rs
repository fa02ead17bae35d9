//! `/session` and `/device/identity`: what started the recording and which devices took part.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::topic::{Topic, TopicRecord};

/// The record version this code writes in `/session`.
pub const VERSION: u32 = 2;

fn version_1() -> u32 {
    1
}

/// `/session`: what started the recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.Session")]
pub struct SessionStart {
    /// Record version ([`VERSION`]); absent (1) in sessions recorded before it existed.
    #[serde(default = "version_1")]
    pub version: u32,
    /// Writing software and its version.
    pub software: String,
    /// Start time (ns since the Unix epoch).
    pub started_unix_ns: u64,
    /// The stand file's path as given.
    pub stand_file: String,
    /// The sweep plan (stepped sine or broadband) as its own serde form.
    #[serde(default)]
    pub plan: Option<serde_json::Value>,
    /// The earlier session a resumed sweep continues.
    #[serde(default)]
    pub resumed_from: Option<String>,
    /// Steps that earlier session completed (not measured again).
    #[serde(default)]
    pub completed_steps_before: Vec<usize>,
}

impl TopicRecord for SessionStart {
    const TOPIC: Topic = Topic::Session;
}

/// Which device an identity belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// The exciter's controller.
    Shaker,
    /// The data acquisition unit.
    Daq,
}

/// `/device/identity`: one device's identity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.DeviceIdentity")]
pub struct DeviceIdentityRecord {
    /// Which device.
    pub role: Role,
    /// Its port.
    pub port: String,
    /// Manufacturer.
    pub manufacturer: String,
    /// Model.
    pub model: String,
    /// Serial number.
    #[serde(default)]
    pub serial: String,
    /// Firmware version.
    #[serde(default)]
    pub firmware: String,
}

impl TopicRecord for DeviceIdentityRecord {
    const TOPIC: Topic = Topic::Identity;
}
