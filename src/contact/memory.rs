//! What the contact sets carry from one step to the next: one memory per contact set, kept in the
//! run's [`Counters`](crate::model::Counters) and written to and read from a checkpoint through one
//! function pair ([`ContactMemory::record`], [`ContactMemory::restore`]).
//!
//! A new contact kind adds its memory type and field here and its entries to [`ContactRecord`].

use super::NodeStatus;

/// What a rigid device (a loading plate or support, with or without a pin) carries from one step to
/// the next; one per rigid body, a body without contact keeps the default (no rotation, no statuses).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DeviceMemory {
    /// Rotation of the body about its pin since t = 0 (rad, in the x-y plane; 0 without a pin).
    pub rotation: f64,
    /// Rotation rate of the body in the last step (rad/s): times the next step's `dt`, the first guess
    /// of its rotation.
    pub rotation_rate: f64,
    /// (grid node, status) of the device's contact nodes at the end of the last step: the first guess
    /// of the next step's active set, so that a resumed run takes the same steps.
    pub statuses: Vec<(usize, NodeStatus)>,
}

/// What the contact between the specimen and the bodies on their own velocity fields carries from one
/// step to the next.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PairMemory {
    /// The closed pairs at the end of the last step (the other body's node copies, sorted): with the
    /// predicted overlap, the first guess of the next step's active set.
    pub closed: Vec<usize>,
}

/// The memory of every contact set of a run: one [`DeviceMemory`] per rigid body and one
/// [`PairMemory`] for the contact between bodies.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ContactMemory {
    /// Per rigid body, in the order of [`Parameters::rigid`](crate::model::Parameters::rigid).
    pub devices: Vec<DeviceMemory>,
    /// The contact between bodies.
    pub pairs: PairMemory,
}

/// The contact memory as a checkpoint's counters store it (format 2: parallel lists, one entry per
/// rigid body, flattened into the counters' JSON object). Every list may be missing or short in a
/// checkpoint written before pins or contact existed.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactRecord {
    /// [`DeviceMemory::rotation`] per rigid body (rad).
    #[serde(default)]
    pub rotations: Vec<f64>,
    /// [`DeviceMemory::rotation_rate`] per rigid body (rad/s).
    #[serde(default)]
    pub rotation_rates: Vec<f64>,
    /// [`DeviceMemory::statuses`] per rigid body.
    #[serde(default)]
    pub contact_statuses: Vec<Vec<(usize, NodeStatus)>>,
    /// [`PairMemory::closed`].
    #[serde(default)]
    pub closed_pairs: Vec<usize>,
}

impl ContactMemory {
    /// The memory at t = 0 of a run with `nrigid` rigid bodies: nothing carried yet.
    pub fn new(nrigid: usize) -> Self {
        Self {
            devices: vec![DeviceMemory::default(); nrigid],
            pairs: PairMemory::default(),
        }
    }

    /// The record a checkpoint stores.
    pub fn record(&self) -> ContactRecord {
        let d = &self.devices;
        ContactRecord {
            rotations: d.iter().map(|m| m.rotation).collect(),
            rotation_rates: d.iter().map(|m| m.rotation_rate).collect(),
            contact_statuses: d.iter().map(|m| m.statuses.clone()).collect(),
            closed_pairs: self.pairs.closed.clone(),
        }
    }

    /// The memory of a run with `nrigid` rigid bodies from a checkpoint's `record`: the entries of a
    /// list that an older checkpoint lacks are the memory at t = 0.
    pub fn restore(record: ContactRecord, nrigid: usize) -> Self {
        let mut statuses = record.contact_statuses.into_iter();
        let devices = (0..nrigid)
            .map(|k| DeviceMemory {
                rotation: record.rotations.get(k).copied().unwrap_or(0.0),
                rotation_rate: record.rotation_rates.get(k).copied().unwrap_or(0.0),
                statuses: statuses.next().unwrap_or_default(),
            })
            .collect();
        Self {
            devices,
            pairs: PairMemory {
                closed: record.closed_pairs,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_record_restores_the_memory() {
        let mut memory = ContactMemory::new(2);
        memory.devices[1] = DeviceMemory {
            rotation: 0.25,
            rotation_rate: -3.0,
            statuses: vec![(7, NodeStatus::Slip(-1)), (8, NodeStatus::Open)],
        };
        memory.pairs.closed = vec![3, 5];
        assert_eq!(ContactMemory::restore(memory.record(), 2), memory);
    }

    #[test]
    fn an_older_record_is_padded_to_every_rigid_body() {
        let record = ContactRecord {
            rotations: vec![0.5],
            ..ContactRecord::default()
        };
        let memory = ContactMemory::restore(record, 2);
        assert_eq!(memory.devices.len(), 2);
        assert_eq!(memory.devices[0].rotation, 0.5);
        assert_eq!(memory.devices[1], DeviceMemory::default());
    }
}
