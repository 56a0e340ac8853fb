//! Operations and commands: the execution-flow requests a task accepts from any thread.
//!
//! A task declares its operations as data ([`OperationDescriptor`]: name, doc, typed
//! parameters) and as a Rust type implementing [`Commands`] (usually an enum with one variant
//! per operation). A sender, realtime or not, calls [`CommandSender::send`]: the command goes
//! into the task's preallocated, bounded, lock-free MPSC queue together with an index into a
//! preallocated pool of status slots, and the sender gets a [`CommandHandle`] on that slot.
//! After its periodic work the task's command processor takes the command, accepts or rejects
//! it (with a [`RejectReason`]), and then evaluates its completion condition every cycle until
//! it is [`CommandStatus::Done`] or [`CommandStatus::Failed`].
//!
//! Why a slot pool instead of an `Arc` per command: a realtime sender must not allocate, and
//! the handle must stay valid while either side still looks at it. Each slot is reference
//! counted by the handle and by the processor; the last one returns it to a lock-free free
//! list. A dropped handle does not cancel the command.
//!
//! Dynamic calls (the control socket's "call any operation by name") go through
//! [`DynCommandSender::send_args`], which parses [`ArgValue`]s into the typed command off the
//! realtime path.

use super::ring::Ring;
use super::sync::{Arc, AtomicU8, Ordering, UnsafeCell};
use super::task::TaskState;
use std::fmt;
use std::time::{Duration, Instant};

/// Type of an operation parameter, for descriptors and dynamic argument checking.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ArgType {
    /// `true`/`false`.
    Bool,
    /// 64-bit signed integer.
    Int,
    /// 64-bit float (an `Int` argument is accepted too).
    Float,
    /// UTF-8 string.
    Str,
}

/// A dynamically typed argument, as parsed from the control socket.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum ArgValue {
    /// Boolean.
    Bool(bool),
    /// Integer.
    Int(i64),
    /// Float.
    Float(f64),
    /// String.
    Str(String),
}

/// A parameter of an operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ParamDescriptor {
    /// Name, with unit suffix where it has one (`position_mm`).
    pub name: &'static str,
    /// Type.
    pub ty: ArgType,
}

impl ParamDescriptor {
    /// A parameter, for `const` tables of operations.
    pub const fn new(name: &'static str, ty: ArgType) -> Self {
        ParamDescriptor { name, ty }
    }
}

/// When the command processor may take the next command after one of this operation was
/// accepted (the paper's Fig. 7: "the next command only when the current one allows").
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum NextCommand {
    /// Only after this command is done or failed (motion-like commands).
    AfterCompletion,
    /// In the next cycle; this command keeps being evaluated in parallel (setting a
    /// parameter, switching a light).
    AfterAcceptance,
}

/// An operation of a task, as data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct OperationDescriptor {
    /// Name used to call it.
    pub name: &'static str,
    /// What it does.
    pub doc: &'static str,
    /// Parameters, in call order.
    pub params: &'static [ParamDescriptor],
    /// Whether later commands wait for this one to complete.
    pub next: NextCommand,
}

impl OperationDescriptor {
    /// An operation, for `const` tables of operations.
    pub const fn new(
        name: &'static str,
        doc: &'static str,
        params: &'static [ParamDescriptor],
        next: NextCommand,
    ) -> Self {
        OperationDescriptor {
            name,
            doc,
            params,
            next,
        }
    }
}

/// Errors turning dynamic arguments into a typed command.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArgError {
    /// No operation with that name.
    #[error("no operation '{0}'")]
    UnknownOperation(String),
    /// Wrong number of arguments.
    #[error("operation '{operation}' takes {expected} argument(s), got {got}")]
    Count {
        /// Operation.
        operation: String,
        /// Parameters declared.
        expected: usize,
        /// Arguments given.
        got: usize,
    },
    /// An argument of the wrong type.
    #[error("operation '{operation}': parameter '{param}' must be {expected:?}")]
    Type {
        /// Operation.
        operation: String,
        /// Parameter name.
        param: String,
        /// Declared type.
        expected: ArgType,
    },
}

/// Checked view of dynamic arguments against a descriptor: the typed accessors a
/// [`Commands::from_args`] implementation uses.
pub struct Args<'a> {
    op: &'static OperationDescriptor,
    args: &'a [ArgValue],
}

impl<'a> Args<'a> {
    /// Finds `operation` in `ops` and checks the argument count.
    pub fn new(
        ops: &'static [OperationDescriptor],
        operation: &str,
        args: &'a [ArgValue],
    ) -> Result<Self, ArgError> {
        let op = ops
            .iter()
            .find(|o| o.name == operation)
            .ok_or_else(|| ArgError::UnknownOperation(operation.to_owned()))?;
        if op.params.len() != args.len() {
            return Err(ArgError::Count {
                operation: op.name.to_owned(),
                expected: op.params.len(),
                got: args.len(),
            });
        }
        Ok(Self { op, args })
    }

    /// The operation found.
    pub fn operation(&self) -> &'static str {
        self.op.name
    }

    fn type_err(&self, i: usize) -> ArgError {
        let p = self.op.params.get(i);
        ArgError::Type {
            operation: self.op.name.to_owned(),
            param: p.map_or("?", |p| p.name).to_owned(),
            expected: p.map_or(ArgType::Str, |p| p.ty),
        }
    }

    /// Argument `i` as a float (integers convert).
    pub fn float(&self, i: usize) -> Result<f64, ArgError> {
        match self.args.get(i) {
            Some(ArgValue::Float(v)) => Ok(*v),
            Some(ArgValue::Int(v)) => Ok(*v as f64),
            _ => Err(self.type_err(i)),
        }
    }

    /// Argument `i` as an integer.
    pub fn int(&self, i: usize) -> Result<i64, ArgError> {
        match self.args.get(i) {
            Some(ArgValue::Int(v)) => Ok(*v),
            _ => Err(self.type_err(i)),
        }
    }

    /// Argument `i` as a bool.
    pub fn bool(&self, i: usize) -> Result<bool, ArgError> {
        match self.args.get(i) {
            Some(ArgValue::Bool(v)) => Ok(*v),
            _ => Err(self.type_err(i)),
        }
    }

    /// Argument `i` as a string.
    pub fn str(&self, i: usize) -> Result<&'a str, ArgError> {
        match self.args.get(i) {
            Some(ArgValue::Str(v)) => Ok(v),
            _ => Err(self.type_err(i)),
        }
    }
}

/// The typed commands of a task: usually an enum with one variant per operation.
pub trait Commands: Send + Sized + 'static {
    /// The operations, as data. Index `i` describes the commands whose
    /// [`operation_index`](Commands::operation_index) is `i`.
    fn operations() -> &'static [OperationDescriptor];
    /// Which operation this command invokes.
    fn operation_index(&self) -> usize;
    /// Builds a command from dynamic arguments (off the realtime path).
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError>;
}

/// The command set of a task without operations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoCommands {}

impl Commands for NoCommands {
    fn operations() -> &'static [OperationDescriptor] {
        &[]
    }
    fn operation_index(&self) -> usize {
        match *self {}
    }
    fn from_args(operation: &str, _args: &[ArgValue]) -> Result<Self, ArgError> {
        Err(ArgError::UnknownOperation(operation.to_owned()))
    }
}

/// Why a task refused a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum RejectReason {
    /// The task cannot take it now (e.g. already moving).
    Busy,
    /// A parameter is out of range or inconsistent; the text says which.
    BadParameters(&'static str),
    /// The task is not running (commands are only accepted in `Running`).
    WrongState(TaskState),
    /// Anything else; the text says what.
    Other(&'static str),
}

impl fmt::Display for RejectReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Busy => write!(f, "busy"),
            Self::BadParameters(why) => write!(f, "bad parameters: {why}"),
            Self::WrongState(s) => write!(f, "task is {s:?}, not Running"),
            Self::Other(why) => write!(f, "{why}"),
        }
    }
}

/// Progress of an accepted command, as evaluated by its completion condition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// Not finished; evaluate again next cycle.
    Running,
    /// The completion condition holds.
    Done,
    /// It cannot complete; the text says why.
    Failed(&'static str),
}

/// Status of a command as seen through its [`CommandHandle`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum CommandStatus {
    /// Queued, not yet looked at by the task.
    Pending,
    /// Accepted; its completion condition is being evaluated.
    Accepted,
    /// Refused.
    Rejected(RejectReason),
    /// Completed.
    Done,
    /// Accepted but could not complete.
    Failed(&'static str),
}

impl CommandStatus {
    /// True for `Rejected`, `Done` and `Failed`: nothing will change any more.
    pub fn is_final(&self) -> bool {
        !matches!(self, Self::Pending | Self::Accepted)
    }
}

/// Errors sending a command.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SendError {
    /// The task's command queue (or its pool of handles) is full.
    #[error("command queue of task '{0}' is full")]
    QueueFull(String),
    /// The dynamic arguments do not fit the operation.
    #[error(transparent)]
    Args(#[from] ArgError),
}

const PENDING: u8 = 0;
const ACCEPTED: u8 = 1;
const REJECTED: u8 = 2;
const DONE: u8 = 3;
const FAILED: u8 = 4;

/// One status slot. `reason` is written once, before the final status is published with
/// release ordering, and read only after an acquire load saw a final status.
struct Slot {
    status: AtomicU8,
    reason: UnsafeCell<CommandStatus>,
    /// Holders: the handle and the processor (2 while both live).
    refs: AtomicU8,
}

/// The pool of status slots of one task's commands.
pub(crate) struct HandlePool {
    slots: Box<[Slot]>,
    free: Ring<u32>,
}

// SAFETY: `reason` is accessed under the publish/acquire protocol documented on `Slot`.
unsafe impl Sync for HandlePool {}
// SAFETY: as above.
unsafe impl Send for HandlePool {}

impl HandlePool {
    fn new(capacity: usize) -> Self {
        let free = Ring::new(capacity);
        let cap = free.capacity();
        for i in 0..cap as u32 {
            // Cannot fail: the ring has exactly `cap` slots.
            let _ = free.push(i);
        }
        Self {
            slots: (0..cap)
                .map(|_| Slot {
                    status: AtomicU8::new(PENDING),
                    reason: UnsafeCell::new(CommandStatus::Pending),
                    refs: AtomicU8::new(0),
                })
                .collect(),
            free,
        }
    }

    fn alloc(pool: &Arc<Self>) -> Option<CommandHandle> {
        let index = pool.free.pop_shared()?;
        let slot = &pool.slots[index as usize];
        slot.status.store(PENDING, Ordering::Relaxed);
        slot.refs.store(2, Ordering::Release);
        Some(CommandHandle {
            pool: pool.clone(),
            index,
        })
    }

    fn status(&self, index: u32) -> CommandStatus {
        let slot = &self.slots[index as usize];
        match slot.status.load(Ordering::Acquire) {
            PENDING => CommandStatus::Pending,
            ACCEPTED => CommandStatus::Accepted,
            DONE => CommandStatus::Done,
            // SAFETY: the final status was published after `reason` was written, and
            // `reason` is never written again while this slot is referenced.
            _ => slot.reason.with(|p| unsafe { *p }),
        }
    }

    fn set(&self, index: u32, status: CommandStatus) {
        let slot = &self.slots[index as usize];
        let code = match status {
            CommandStatus::Pending => PENDING,
            CommandStatus::Accepted => ACCEPTED,
            CommandStatus::Done => DONE,
            CommandStatus::Rejected(_) => REJECTED,
            CommandStatus::Failed(_) => FAILED,
        };
        if code == REJECTED || code == FAILED {
            // SAFETY: only the processor writes `reason`, once, before publishing a final
            // status; readers look at it only after seeing that status.
            slot.reason.with_mut(|p| unsafe { *p = status });
        }
        slot.status.store(code, Ordering::Release);
    }

    fn release(&self, index: u32) {
        if self.slots[index as usize]
            .refs
            .fetch_sub(1, Ordering::AcqRel)
            == 1
        {
            // Cannot fail: at most `capacity` indices exist.
            let _ = self.free.push(index);
        }
    }
}

/// The sender's view of one command. Poll it from realtime code with [`status`]; wait for it
/// from non-realtime code with [`wait`]. Dropping it does not cancel the command.
///
/// [`status`]: CommandHandle::status
/// [`wait`]: CommandHandle::wait
pub struct CommandHandle {
    pool: Arc<HandlePool>,
    index: u32,
}

impl CommandHandle {
    /// Current status. Wait-free.
    #[inline]
    pub fn status(&self) -> CommandStatus {
        self.pool.status(self.index)
    }

    /// Waits until the status is final or `timeout` passes, returning the last status seen.
    /// Polls with a sleep that grows from 50 µs to 2 ms: the realtime side never has to wake
    /// anybody (no syscall in the step). Not for realtime code.
    pub fn wait(&self, timeout: Duration) -> CommandStatus {
        self.wait_until(|s| s.is_final(), timeout)
    }

    /// Waits until the command is no longer `Pending` (accepted or rejected) or `timeout`
    /// passes.
    pub fn wait_accepted(&self, timeout: Duration) -> CommandStatus {
        self.wait_until(|s| *s != CommandStatus::Pending, timeout)
    }

    fn wait_until(
        &self,
        done: impl Fn(&CommandStatus) -> bool,
        timeout: Duration,
    ) -> CommandStatus {
        let start = Instant::now();
        let mut nap = Duration::from_micros(50);
        loop {
            let s = self.status();
            if done(&s) || start.elapsed() >= timeout {
                return s;
            }
            std::thread::sleep(nap.min(timeout.saturating_sub(start.elapsed())));
            nap = (nap * 2).min(Duration::from_millis(2));
        }
    }
}

impl fmt::Debug for CommandHandle {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CommandHandle")
            .field("status", &self.status())
            .finish()
    }
}

impl Drop for CommandHandle {
    fn drop(&mut self) {
        self.pool.release(self.index);
    }
}

/// What the task side holds for a command it took from the queue.
pub(crate) struct Ticket {
    pool: Arc<HandlePool>,
    index: u32,
}

impl Ticket {
    pub(crate) fn set(&self, status: CommandStatus) {
        self.pool.set(self.index, status);
    }
}

impl Drop for Ticket {
    fn drop(&mut self) {
        self.pool.release(self.index);
    }
}

pub(crate) struct QueueShared<C> {
    task: String,
    queue: Ring<(C, u32)>,
    pool: Arc<HandlePool>,
    state: std::sync::Arc<super::task::StateCell>,
}

/// Sends commands to one task. `Clone`; usable from any thread, realtime or not.
pub struct CommandSender<C> {
    shared: Arc<QueueShared<C>>,
}

impl<C> Clone for CommandSender<C> {
    fn clone(&self) -> Self {
        Self {
            shared: self.shared.clone(),
        }
    }
}

impl<C: Commands> CommandSender<C> {
    /// Queues `command`. Never blocks or allocates. A task that is not running rejects it at
    /// once (`Rejected(WrongState)`); a full queue is an error.
    pub fn send(&self, command: C) -> Result<CommandHandle, SendError> {
        let s = &*self.shared;
        let full = || SendError::QueueFull(s.task.clone());
        let Some(handle) = HandlePool::alloc(&s.pool) else {
            return Err(full());
        };
        let state = s.state.get();
        if state != TaskState::Running {
            s.pool.set(
                handle.index,
                CommandStatus::Rejected(RejectReason::WrongState(state)),
            );
            s.pool.release(handle.index);
            return Ok(handle);
        }
        if s.queue.push((command, handle.index)).is_err() {
            // The processor will never see this slot: drop its reference too.
            s.pool.release(handle.index);
            return Err(full());
        }
        Ok(handle)
    }

    /// The task's operations.
    pub fn operations(&self) -> &'static [OperationDescriptor] {
        C::operations()
    }

    /// Name of the receiving task.
    pub fn task(&self) -> &str {
        &self.shared.task
    }
}

/// Sending commands by operation name and dynamic arguments (control socket, peers that only
/// know the name).
pub trait DynCommandSender: Send + Sync {
    /// Builds the typed command from `args` and sends it.
    fn send_args(&self, operation: &str, args: &[ArgValue]) -> Result<CommandHandle, SendError>;
    /// The task's operations.
    fn operations(&self) -> &'static [OperationDescriptor];
}

impl<C: Commands> DynCommandSender for CommandSender<C> {
    fn send_args(&self, operation: &str, args: &[ArgValue]) -> Result<CommandHandle, SendError> {
        let cmd = C::from_args(operation, args)?;
        self.send(cmd)
    }
    fn operations(&self) -> &'static [OperationDescriptor] {
        C::operations()
    }
}

/// The task side of the queue (owned by the task's runner; not `Clone`).
pub(crate) struct CommandReceiver<C> {
    shared: Arc<QueueShared<C>>,
}

impl<C: Send> CommandReceiver<C> {
    pub(crate) fn pop(&mut self) -> Option<(C, Ticket)> {
        let (cmd, index) = self.shared.queue.pop_single()?;
        Some((
            cmd,
            Ticket {
                pool: self.shared.pool.clone(),
                index,
            },
        ))
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.shared.queue.len() == 0
    }
}

/// Creates the queue of a task: `capacity` queued commands and as many live handles.
pub(crate) fn command_queue<C: Commands>(
    task: &str,
    capacity: usize,
    state: std::sync::Arc<super::task::StateCell>,
) -> (CommandSender<C>, CommandReceiver<C>) {
    let queue = Ring::new(capacity);
    let pool = Arc::new(HandlePool::new(queue.capacity() * 2));
    let shared = Arc::new(QueueShared {
        task: task.to_owned(),
        queue,
        pool,
        state,
    });
    (
        CommandSender {
            shared: shared.clone(),
        },
        CommandReceiver { shared },
    )
}

#[cfg(all(test, loom))]
mod loom_tests {
    use super::*;

    enum C {
        A,
    }

    impl Commands for C {
        fn operations() -> &'static [OperationDescriptor] {
            &[]
        }
        fn operation_index(&self) -> usize {
            0
        }
        fn from_args(operation: &str, _: &[ArgValue]) -> Result<Self, ArgError> {
            Err(ArgError::UnknownOperation(operation.to_owned()))
        }
    }

    #[test]
    fn two_senders_one_processor_statuses_and_slot_reuse() {
        loom::model(|| {
            let state = std::sync::Arc::new(crate::rt::task::StateCell::new(TaskState::Running));
            let (tx, mut rx) = command_queue::<C>("t", 2, state);
            let tx2 = tx.clone();
            let t = loom::thread::spawn(move || tx2.send(C::A).ok());
            // This handle is dropped before the command is processed: its slot must only be
            // reused once the processor is done with it too.
            drop(tx.send(C::A));
            let mut done = 0;
            while done < 2 {
                match rx.pop() {
                    Some((C::A, ticket)) => {
                        ticket.set(CommandStatus::Rejected(RejectReason::Busy));
                        done += 1;
                    }
                    None => loom::thread::yield_now(),
                }
            }
            let h2 = t.join().unwrap().expect("queue has room");
            assert_eq!(h2.status(), CommandStatus::Rejected(RejectReason::Busy));
            // Every slot is back in the pool: a full pool's worth can be allocated again.
            let again = tx.send(C::A).expect("slot reused");
            assert_eq!(again.status(), CommandStatus::Pending);
        });
    }
}
