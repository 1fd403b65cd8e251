//! Object-oriented extensions (IEC 61131-3 3rd edition as CODESYS has them): methods,
//! properties, interfaces, inheritance, actions.

use crate::codegen::Gen;

impl Gen<'_> {
    /// The function block whose variables the current POU's body sees besides its own (the
    /// owner of a method or action), if `name` is one of them.
    pub(crate) fn var_owner(&self, _name: &str) -> Option<usize> {
        None
    }

    /// The type of variable `name` of the current POU's owner.
    pub(crate) fn owner_var_type(&self, _name: &str) -> Option<crate::types::Type> {
        None
    }

    /// Whether POU `pi` is a METHOD (or a property accessor).
    pub(crate) fn is_method(&self, _pi: usize) -> bool {
        false
    }

    /// Whether function block `class` is `base` or derived from it.
    pub(crate) fn derives_from(&self, class: usize, base: usize) -> bool {
        class == base
    }

    /// Whether function block `class` implements interface `interface`.
    pub(crate) fn implements(&self, _class: usize, _interface: usize) -> bool {
        false
    }

    /// Whether interface `a` is `b` or extends it.
    pub(crate) fn interface_extends(&self, a: usize, b: usize) -> bool {
        a == b
    }
}
