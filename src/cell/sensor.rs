//! The sensor task, first on the servo thread: reads the encoders and digital inputs the
//! hardware latched at the end of the previous cycle, checks every axis against its range
//! (a reading outside it is a broken encoder or a crash: `range_error`, once per excursion),
//! and publishes the measurement for the robot and the PID.

use super::names;
use super::types::{Feedback, RangeError, Vec3, AXES};
use crate::rt::prelude::*;

/// The sensor task.
pub struct Sensor {
    raw: Option<DataReader<Feedback>>,
    out: Option<DataWriter<Feedback>>,
    range_error: Option<EventSource<RangeError>>,
    reading: Feedback,
    out_of_range: [bool; AXES],
    /// Lowest valid reading per axis, mm.
    pub min_mm: Vec3,
    /// Highest valid reading per axis, mm.
    pub max_mm: Vec3,
}

impl Sensor {
    /// A sensor accepting readings in `[min_mm, max_mm]`.
    pub fn new(min_mm: Vec3, max_mm: Vec3) -> Self {
        Self {
            raw: None,
            out: None,
            range_error: None,
            reading: Feedback::default(),
            out_of_range: [false; AXES],
            min_mm,
            max_mm,
        }
    }
}

impl Task for Sensor {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.raw = Some(ctx.input(names::FEEDBACK));
        self.out = Some(ctx.output(names::SENSED));
        self.range_error = Some(ctx.event("range_error"));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.raw {
            r.get(&mut self.reading);
        }
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        for axis in 0..AXES {
            let p = self.reading.position_mm[axis];
            let out = !(self.min_mm[axis]..=self.max_mm[axis]).contains(&p);
            if out && !self.out_of_range[axis] {
                if let Some(ev) = &mut self.range_error {
                    ev.emit(RangeError {
                        axis,
                        position_mm: p,
                    });
                }
            }
            self.out_of_range[axis] = out;
        }
        if let Some(o) = &mut self.out {
            o.set(self.reading);
        }
        Ok(())
    }
}
