//! Located and shared variables, the safe values of outputs, and the CONFIGURATION: tasks and
//! program instances.

use super::*;

impl Sema<'_> {
    /// Records the `{attribute 'safe' := 'VALUE'}` of a located output (declared in `pou`,
    /// or a global); reports one on any other declaration or with a value that does not fit.
    pub(super) fn safe_default(
        &mut self,
        d: &VarDecl,
        ty: &Type,
        location: Option<Location>,
        pou: Option<usize>,
    ) {
        let Some((value, span)) = &d.safe else { return };
        let Some(location) = location.filter(|l| l.area == plc_vm::located::Area::Output) else {
            if d.at.is_none() || !ty.is_error() {
                self.diags.error(codes::SAFE_ATTRIBUTE,
                    *span,
                    "the attribute 'safe' gives a located output (`AT %Q...`) the value it takes when the outputs go safe; this declaration is not one",
                );
            }
            return;
        };
        let Type::Elem(e) = ty else { return };
        match crate::monitor::parse_elem(*e, value) {
            Ok(cell) => {
                let bits = location.width.bytes() * 8;
                let cell = if bits >= 64 {
                    cell
                } else {
                    cell & ((1u64 << bits) - 1)
                };
                for n in &d.names {
                    self.prog.safe.push(SafeDefault {
                        pou,
                        name: n.name.clone(),
                        text: n.text.clone(),
                        width: location.width.bytes() as u8,
                        value: cell,
                    });
                }
            }
            Err(why) => self.diags.error(
                codes::SAFE_ATTRIBUTE,
                *span,
                format!("the safe value: {why}"),
            ),
        }
    }

    /// Reports an `{attribute 'shared'}` pragma on a declaration that cannot be shared.
    pub(super) fn no_shared_attribute(&mut self, d: &VarDecl, what: &str) {
        if let Some(a) = d.shared {
            self.diags.error(
                codes::SHARED_ATTRIBUTE,
                a.span,
                format!("the attribute 'shared' applies to global variables only, not to {what}"),
            );
        }
    }

    /// The checked direction of a global's `{attribute 'shared'}` pragma, if it has one: an
    /// elementary type other than STRING (the other project's bytes are taken as they are,
    /// so no type with an invariant such as a length), not located, and not a CONSTANT that
    /// the other project would overwrite.
    pub(super) fn shared_global(
        &mut self,
        d: &VarDecl,
        block: &VarBlock,
        ty: &Type,
    ) -> Option<plc_vm::image::SharedDirection> {
        use plc_vm::image::SharedDirection;
        let a = d.shared?;
        if a.direction == SharedDirection::Valid {
            if !matches!(ty, Type::Elem(crate::types::Elem::Bool) | Type::Error) {
                self.diags.error(codes::SHARED_VARIABLE,
                    d.ty.span(),
                    format!(
                        "the validity flag of the shared globals (`'valid'`) must be a BOOL, not {}",
                        self.prog.type_name(ty)
                    ),
                );
                return None;
            }
            let names = d.names.len()
                + self
                    .prog
                    .shared
                    .iter()
                    .filter(|s| s.direction == SharedDirection::Valid)
                    .count();
            if names > 1 {
                self.diags.error(
                    codes::SHARED_VARIABLE,
                    a.span,
                    "a program has at most one validity flag of its shared globals",
                );
                return None;
            }
        }
        let elementary = match ty {
            Type::Elem(e) => crate::monitor::ValueKind::Elem(*e)
                .var_type()
                .is_some_and(|t| t.mem_type().is_some()),
            Type::Error => return None,
            _ => false,
        };
        if !elementary {
            self.diags.error(codes::SHARED_VARIABLE,
                d.ty.span(),
                format!(
                    "a shared variable must have an elementary type (BOOL, integers, REAL, LREAL, bit strings, the date/time types, CHAR, WCHAR), not {}",
                    self.prog.type_name(ty)
                ),
            );
            return None;
        }
        if let Some((_, span)) = &d.at {
            self.diags.error(codes::SHARED_VARIABLE,
                *span,
                "a shared variable cannot be located (`AT %...`): it lives in the shared segment, not in the process image",
            );
            return None;
        }
        if block.constant && a.direction != SharedDirection::Write {
            self.diags.error(codes::SHARED_VARIABLE,
                a.span,
                "a CONSTANT cannot be read from another project or be the validity flag (it would change)",
            );
            return None;
        }
        Some(a.direction)
    }

    /// The checked direct address of a declaration (`AT %...`), if it has one: only in
    /// `allowed` places (a PROGRAM's VAR, VAR_GLOBAL), for one variable of an elementary type
    /// of the address's size.
    pub(super) fn location(&mut self, d: &VarDecl, ty: &Type, allowed: bool) -> Option<Location> {
        let (text, span) = d.at.as_ref()?;
        if !allowed {
            self.diags.error(codes::LOCATED_NOT_ALLOWED,
                *span,
                "located variables (`AT %...`) are allowed only in a PROGRAM's VAR block and in VAR_GLOBAL",
            );
            return None;
        }
        if d.names.len() > 1 {
            self.diags.error(
                codes::LOCATED_NOT_ALLOWED,
                *span,
                "a direct address locates exactly one variable",
            );
            return None;
        }
        let location = match Location::parse(text) {
            Ok(l) => l,
            Err(e) => {
                self.diags.error(
                    codes::DIRECT_ADDRESS,
                    *span,
                    format!("invalid direct address `%{text}`: {e}"),
                );
                return None;
            }
        };
        let var_type = match ty {
            Type::Elem(e) => crate::monitor::ValueKind::Elem(*e).var_type(),
            _ => None,
        };
        if !var_type.is_some_and(|t| location.width.fits(t)) {
            if !ty.is_error() {
                use plc_vm::located::Width;
                let (size, expected) = match location.width {
                    Width::Bit => ("a bit", "BOOL"),
                    Width::Byte => ("a byte", "BYTE, SINT, USINT or CHAR"),
                    Width::Word => ("a word (2 bytes)", "WORD, INT, UINT or WCHAR"),
                    Width::DWord => ("a double word (4 bytes)", "DWORD, DINT, UDINT or REAL"),
                    Width::LWord => (
                        "a long word (8 bytes)",
                        "LWORD, LINT, ULINT, LREAL or a date/time type (TIME, LTIME, DATE, TOD, DT and the long forms)",
                    ),
                };
                self.diags.error(
                    codes::DIRECT_ADDRESS,
                    d.ty.span(),
                    format!("`%{text}` is {size}: its variable must be {expected}"),
                );
            }
            return None;
        }
        Some(location)
    }

    pub(super) fn task_time(&mut self, e: &Expr) -> Option<i64> {
        match const_eval(&self.prog, &(), e) {
            Some(ConstVal::Time(t)) if t > 0 => Some(t as i64),
            _ => {
                self.diags.error(
                    codes::TASK_DECLARATION,
                    e.span,
                    "task INTERVAL must be a positive TIME literal such as T#10ms",
                );
                None
            }
        }
    }
    /// Records a TASK of the CONFIGURATION.
    fn declare_task(&mut self, t: &TaskDecl) {
        let interval = t
            .interval
            .as_ref()
            .and_then(|e| self.task_time(e))
            .unwrap_or(0);
        let single = match &t.single {
            Some(Expr {
                kind: ExprKind::Name(n),
                ..
            }) => match self.prog.global(&n.name) {
                Some(g) if g.ty == Type::BOOL => Some(n.name.clone()),
                _ => {
                    self.diags.error(
                        codes::TASK_DECLARATION,
                        n.span,
                        "SINGLE must name a global BOOL variable",
                    );
                    None
                }
            },
            Some(e) => {
                self.diags.error(
                    codes::TASK_DECLARATION,
                    e.span,
                    "SINGLE must name a global BOOL variable",
                );
                None
            }
            None => None,
        };
        if t.interval.is_none() && t.single.is_none() {
            self.diags.error(
                codes::TASK_DECLARATION,
                t.name.span,
                "a task needs INTERVAL or SINGLE",
            );
        }
        let priority = match &t.priority {
            Some(e) => match const_eval(&self.prog, &(), e) {
                Some(ConstVal::Int(p)) if (0..=u32::MAX as i128).contains(&p) => p as u32,
                _ => {
                    self.diags.error(
                        codes::TASK_DECLARATION,
                        e.span,
                        "PRIORITY must be a non-negative integer",
                    );
                    0
                }
            },
            None => 0,
        };
        if self.prog.tasks.iter().any(|x| x.name == t.name.name) {
            self.diags.error(
                codes::DUPLICATE_CONFIGURATION_NAME,
                t.name.span,
                format!("task `{}` is declared twice", t.name.text),
            );
        }
        self.prog.tasks.push(TaskDef {
            name: t.name.name.clone(),
            interval_ns: interval,
            single,
            priority,
            programs: Vec::new(),
        });
    }

    /// Allocates a program instance of the CONFIGURATION and attaches it to its task.
    fn declare_program_instance(&mut self, b: &ProgramBinding) {
        let full = qualified(&b.program_type.name, self.prog.pou_by_name.keys())
            .ok()
            .flatten()
            .unwrap_or_default();
        let Some(&pi) = self
            .prog
            .pou_by_name
            .get(&full)
            .filter(|&&i| self.prog.pous[i].kind == PouKind::Program)
        else {
            self.diags.error(
                codes::UNKNOWN_PROGRAM,
                b.program_type.span,
                format!("unknown PROGRAM `{}`", b.program_type.text),
            );
            return;
        };
        if self
            .prog
            .instances
            .iter()
            .any(|x| x.name.eq_ignore_ascii_case(&b.instance.text))
        {
            self.diags.error(
                codes::DUPLICATE_CONFIGURATION_NAME,
                b.instance.span,
                format!("program instance `{}` is declared twice", b.instance.text),
            );
            return;
        }
        let (sz, _) = (self.prog.pous[pi].frame_size, 8);
        let addr = self.prog.alloc(sz, 8);
        self.prog.instances.push(ProgramInstance {
            name: b.instance.text.clone(),
            pou: pi,
            addr,
        });
        let task_idx = match &b.task {
            Some(t) => match self.prog.tasks.iter().position(|x| x.name == t.name) {
                Some(i) => i,
                None => {
                    self.diags.error(
                        codes::UNKNOWN_TASK,
                        t.span,
                        format!("unknown task `{}`", t.text),
                    );
                    return;
                }
            },
            None => {
                // A program without a task runs cyclically at the base tick.
                self.prog.tasks.push(TaskDef {
                    name: format!("__{}", b.instance.name),
                    interval_ns: 0,
                    single: None,
                    priority: u32::MAX,
                    programs: Vec::new(),
                });
                self.prog.tasks.len() - 1
            }
        };
        self.prog.tasks[task_idx]
            .programs
            .push((b.instance.text.clone(), pi));
    }

    /// Builds the task list from the CONFIGURATION, or one implicit cyclic task running the
    /// single PROGRAM (`program_override` picks one when there are several).
    pub(super) fn configure(&mut self, program_override: Option<&str>, library: bool) {
        let unit = self.unit;
        if unit.configs.len() > 1 {
            self.diags.error(
                codes::ONE_CONFIGURATION,
                unit.configs[1].name.span,
                "only one CONFIGURATION is supported",
            );
        }
        if let Some(cfg) = unit.configs.first() {
            self.prog.has_configuration = true;
            for res in &cfg.resources {
                for t in &res.tasks {
                    self.declare_task(t);
                }
            }
            for res in &cfg.resources {
                for b in &res.programs {
                    self.declare_program_instance(b);
                }
            }
            return;
        }
        if library {
            return;
        }
        let programs: Vec<usize> = (0..self.prog.pous.len())
            .filter(|&i| {
                let p = &self.prog.pous[i];
                p.kind == PouKind::Program && !p.builtin && p.member.is_none()
            })
            .collect();
        let chosen = match program_override {
            Some(name) => {
                let up = name.to_ascii_uppercase();
                match programs.iter().find(|&&i| self.prog.pous[i].name == up) {
                    Some(&i) => Some(i),
                    None => {
                        self.diags.error(
                            codes::UNKNOWN_PROGRAM,
                            Span::default(),
                            format!("there is no PROGRAM named `{name}`"),
                        );
                        None
                    }
                }
            }
            None => match programs.len() {
                0 => None,
                1 => Some(programs[0]),
                _ => {
                    let p = &self.prog.pous[programs[1]];
                    self.diags.error(
                        codes::PROGRAM_SELECTION,
                        p.span,
                        "several PROGRAMs and no CONFIGURATION: choose one with --program",
                    );
                    None
                }
            },
        };
        if let Some(pi) = chosen {
            let addr = self.prog.alloc(self.prog.pous[pi].frame_size, 8);
            let name = self.prog.pous[pi].text.clone();
            self.prog.instances.push(ProgramInstance {
                name: name.clone(),
                pou: pi,
                addr,
            });
            self.prog.tasks.push(TaskDef {
                name: "__MAIN".into(),
                interval_ns: 0,
                single: None,
                priority: 0,
                programs: vec![(name, pi)],
            });
        }
    }
}
