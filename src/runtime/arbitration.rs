//! Brothers and arbitration: schemas run together by one father, of which one
//! iterates at a time (4.3 declared it; this implements it).

use std::{
    panic::{AssertUnwindSafe, catch_unwind},
    sync::Arc,
};

use parking_lot::Mutex;

/// Picks the winner among ready brothers: gets their names in brother order and
/// returns the index of the winner.
pub type Arbitration = Arc<dyn Fn(&[&str]) -> usize + Send + Sync>;

/// Brothers: schemas run together by one father, of which one iterates at a time.
pub struct BrotherGroup {
    names: Vec<String>,
    arbitration: Option<Arbitration>,
    state: Mutex<(Vec<bool>, Option<usize>)>,
}

impl BrotherGroup {
    pub(super) fn new(names: Vec<String>, arbitration: Option<Arbitration>) -> Arc<Self> {
        let n = names.len();
        Arc::new(BrotherGroup {
            names,
            arbitration,
            state: Mutex::new((vec![false; n], None)),
        })
    }

    /// Records whether brother `me` is ready and returns whether it is the winner.
    pub(super) fn decide(&self, me: usize, ready: bool) -> bool {
        let mut s = self.state.lock();
        s.0[me] = ready;
        let candidates: Vec<usize> = (0..self.names.len()).filter(|&i| s.0[i]).collect();
        s.1 = if candidates.is_empty() {
            None
        } else {
            let names: Vec<&str> = candidates.iter().map(|&i| self.names[i].as_str()).collect();
            let pick = match &self.arbitration {
                Some(f) => catch_unwind(AssertUnwindSafe(|| f(&names))).unwrap_or(0),
                None => 0,
            };
            Some(candidates[pick.min(candidates.len() - 1)])
        };
        s.1 == Some(me)
    }

    /// The current winner's name.
    pub fn winner(&self) -> Option<String> {
        self.winner_index().map(|i| self.names[i].clone())
    }

    pub(super) fn winner_index(&self) -> Option<usize> {
        self.state.lock().1
    }
}

/// Who ran a schema.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Father {
    /// The shell, the GUI or the conf file.
    Human,
    Schema(String),
}
