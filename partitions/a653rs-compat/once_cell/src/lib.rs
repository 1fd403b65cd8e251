//! `once_cell::sync::OnceCell` without `std`, for the a653rs-linux example partitions built
//! for Warden (`cargo xtask a653rs-examples`): their programs name this crate `once_cell`
//! (a dependency rename in the generated manifest). The examples set their cells in the
//! initialisation and read them in processes; a `get_or_init` racing another one spins
//! until that one has finished (`spin::Once`), which a higher-priority process must not
//! do to a lower-priority one on one core.
#![no_std]

pub mod sync {
    /// A cell written at most once.
    pub struct OnceCell<T>(spin::Once<T>);

    impl<T> Default for OnceCell<T> {
        fn default() -> Self {
            Self::new()
        }
    }

    impl<T> OnceCell<T> {
        pub const fn new() -> Self {
            OnceCell(spin::Once::new())
        }

        /// The value, once set.
        pub fn get(&self) -> Option<&T> {
            self.0.get()
        }

        /// Sets the value; `Err(value)` if it was set before.
        pub fn set(&self, value: T) -> Result<(), T> {
            let mut value = Some(value);
            self.0.call_once(|| value.take().expect("taken once"));
            value.map_or(Ok(()), Err)
        }

        /// The value, set by `init` if it was not.
        pub fn get_or_init(&self, init: impl FnOnce() -> T) -> &T {
            self.0.call_once(init)
        }
    }

    #[cfg(test)]
    mod tests {
        use super::OnceCell;

        #[test]
        fn set_once_then_refused() {
            static CELL: OnceCell<u32> = OnceCell::new();
            assert_eq!(CELL.get(), None);
            assert_eq!(CELL.set(1), Ok(()));
            assert_eq!(CELL.set(2), Err(2));
            assert_eq!(CELL.get(), Some(&1));
            assert_eq!(*CELL.get_or_init(|| 3), 1);
        }
    }
}
