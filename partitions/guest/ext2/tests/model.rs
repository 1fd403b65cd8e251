//! Random operations against an in-memory model (paths to contents), checking every result
//! and every read, across remounts; e2fsck -fn must be clean at the end.

mod common;

use std::collections::BTreeMap;

use common::*;
use ext2::{Error, Ext2, FormatOptions, ROOT_INO};
use proptest::prelude::*;

#[derive(Clone, Debug)]
enum Op {
    Create(String),
    Mkdir(String),
    Symlink(String, usize),
    Write(String, u64, usize, u8),
    Truncate(String, u64),
    Unlink(String),
    Rmdir(String),
    Rename(String, String),
    Link(String, String),
    Remount,
}

/// A path's node; files and symbolic links carry an id, so that two names are the same
/// node (hard links) only when their ids are equal, not when their contents are.
#[derive(Clone, Debug, PartialEq)]
enum MNode {
    Dir,
    File(u32),
    Symlink(u32, Vec<u8>),
}

#[derive(Default)]
struct Model {
    paths: BTreeMap<String, MNode>,
    files: BTreeMap<u32, Vec<u8>>,
    next_id: u32,
}

fn parent_of(path: &str) -> &str {
    path.rsplit_once('/').map_or("", |(p, _)| p)
}

impl Model {
    /// The parent directory of `path` must exist and be a directory.
    fn check_parent(&self, path: &str) -> Result<(), Error> {
        let mut prefix = String::new();
        for name in parent_of(path).split('/').filter(|n| !n.is_empty()) {
            if !prefix.is_empty() {
                prefix.push('/');
            }
            prefix.push_str(name);
            match self.paths.get(&prefix) {
                None => return Err(Error::NotFound),
                Some(MNode::Dir) => {}
                Some(_) => return Err(Error::NotDir),
            }
        }
        Ok(())
    }

    fn children(&self, dir: &str) -> impl Iterator<Item = &String> {
        let prefix = format!("{dir}/");
        self.paths.keys().filter(move |p| p.starts_with(&prefix))
    }

    fn new_node(&mut self, path: &str, node: MNode) -> Result<(), Error> {
        self.check_parent(path)?;
        if self.paths.contains_key(path) {
            return Err(Error::Exists);
        }
        self.paths.insert(path.to_string(), node);
        Ok(())
    }

    fn file(&self, path: &str) -> Result<u32, Error> {
        self.check_parent(path)?;
        match self.paths.get(path) {
            None => Err(Error::NotFound),
            Some(MNode::Dir) => Err(Error::IsDir),
            Some(MNode::Symlink(..)) => Err(Error::Invalid),
            Some(MNode::File(id)) => Ok(*id),
        }
    }

    fn apply(&mut self, op: &Op) -> Result<(), Error> {
        match op {
            Op::Create(p) => {
                let id = self.next_id;
                self.new_node(p, MNode::File(id))?;
                self.next_id += 1;
                self.files.insert(id, Vec::new());
                Ok(())
            }
            Op::Mkdir(p) => self.new_node(p, MNode::Dir),
            Op::Symlink(p, len) => {
                self.new_node(p, MNode::Symlink(self.next_id, target(*len)))?;
                self.next_id += 1;
                Ok(())
            }
            Op::Write(p, offset, len, seed) => {
                let id = self.file(p)?;
                let data = self.files.get_mut(&id).unwrap();
                if *len > 0 {
                    let end = *offset as usize + len;
                    if data.len() < end {
                        data.resize(end, 0);
                    }
                    data[*offset as usize..end].copy_from_slice(&pattern(*len, u32::from(*seed)));
                }
                Ok(())
            }
            Op::Truncate(p, len) => {
                let id = self.file(p)?;
                self.files.get_mut(&id).unwrap().resize(*len as usize, 0);
                Ok(())
            }
            Op::Unlink(p) => {
                self.check_parent(p)?;
                match self.paths.get(p) {
                    None => Err(Error::NotFound),
                    Some(MNode::Dir) => Err(Error::IsDir),
                    Some(_) => {
                        self.paths.remove(p);
                        Ok(())
                    }
                }
            }
            Op::Rmdir(p) => {
                self.check_parent(p)?;
                match self.paths.get(p) {
                    None => Err(Error::NotFound),
                    Some(MNode::Dir) if self.children(p).next().is_some() => Err(Error::NotEmpty),
                    Some(MNode::Dir) => {
                        self.paths.remove(p);
                        Ok(())
                    }
                    Some(_) => Err(Error::NotDir),
                }
            }
            Op::Link(from, to) => {
                self.check_parent(from)?;
                let source = self.paths.get(from).cloned().ok_or(Error::NotFound)?;
                self.check_parent(to)?;
                if self.paths.contains_key(to) {
                    return Err(Error::Exists);
                }
                if source == MNode::Dir {
                    return Err(Error::NotPermitted);
                }
                self.paths.insert(to.clone(), source);
                Ok(())
            }
            Op::Rename(from, to) => self.rename(from, to),
            Op::Remount => Ok(()),
        }
    }

    fn rename(&mut self, from: &str, to: &str) -> Result<(), Error> {
        self.check_parent(from)?;
        self.check_parent(to)?;
        let source = self.paths.get(from).cloned().ok_or(Error::NotFound)?;
        let target = self.paths.get(to).cloned();
        if from == to
            || (target.is_some() && target == Some(source.clone()) && source != MNode::Dir)
        {
            return Ok(());
        }
        let is_dir = source == MNode::Dir;
        if is_dir && to.starts_with(&format!("{from}/")) {
            return Err(Error::Invalid);
        }
        match (is_dir, &target) {
            (true, Some(t)) if *t != MNode::Dir => return Err(Error::NotDir),
            (false, Some(MNode::Dir)) => return Err(Error::IsDir),
            (true, Some(_)) if self.children(to).next().is_some() => return Err(Error::NotEmpty),
            _ => {}
        }
        self.paths.remove(to);
        let moved: Vec<String> = std::iter::once(from.to_string())
            .chain(self.children(from).cloned())
            .collect();
        for old in moved {
            let node = self.paths.remove(&old).unwrap();
            self.paths
                .insert(format!("{to}{}", &old[from.len()..]), node);
        }
        Ok(())
    }

    fn tree(&self) -> Tree {
        let mut tree = Tree::new();
        tree.insert(String::new(), Node::Dir);
        for (path, node) in &self.paths {
            let node = match node {
                MNode::Dir => Node::Dir,
                MNode::File(id) => Node::File(self.files[id].clone()),
                MNode::Symlink(_, t) => Node::Symlink(t.clone()),
            };
            tree.insert(path.clone(), node);
        }
        tree
    }
}

fn target(len: usize) -> Vec<u8> {
    (0..len).map(|i| b'a' + (i % 26) as u8).collect()
}

/// Runs an operation on the file system, releasing orphans at once.
fn run(fs: &mut Ext2<MemDisk>, op: &Op) -> Result<(), Error> {
    let release = |fs: &mut Ext2<MemDisk>, orphan: Option<u32>| match orphan {
        Some(ino) => fs.release(ino),
        None => Ok(()),
    };
    match op {
        Op::Create(p) => {
            let (dir, name) = parent(fs, p)?;
            fs.create(dir, name.as_bytes(), 0o644).map(drop)
        }
        Op::Mkdir(p) => {
            let (dir, name) = parent(fs, p)?;
            fs.mkdir(dir, name.as_bytes(), 0o755).map(drop)
        }
        Op::Symlink(p, len) => {
            let (dir, name) = parent(fs, p)?;
            fs.symlink(dir, name.as_bytes(), &target(*len)).map(drop)
        }
        Op::Write(p, offset, len, seed) => {
            let ino = resolve(fs, p)?;
            let n = fs.write(ino, *offset, &pattern(*len, u32::from(*seed)))?;
            assert_eq!(n, *len);
            Ok(())
        }
        Op::Truncate(p, len) => {
            let ino = resolve(fs, p)?;
            fs.truncate(ino, *len)
        }
        Op::Unlink(p) => {
            let (dir, name) = parent(fs, p)?;
            let orphan = fs.unlink(dir, name.as_bytes())?;
            release(fs, orphan)
        }
        Op::Rmdir(p) => {
            let (dir, name) = parent(fs, p)?;
            let orphan = fs.rmdir(dir, name.as_bytes())?;
            release(fs, Some(orphan))
        }
        Op::Link(from, to) => {
            let source = resolve(fs, from)?;
            let (dir, name) = parent(fs, to)?;
            fs.link(dir, name.as_bytes(), source)
        }
        Op::Rename(from, to) => {
            let (old_dir, old_name) = parent(fs, from)?;
            let (new_dir, new_name) = parent(fs, to)?;
            let orphan = fs.rename(old_dir, old_name.as_bytes(), new_dir, new_name.as_bytes())?;
            release(fs, orphan)
        }
        Op::Remount => unreachable!(),
    }
}

/// Paths of one to three names out of three, mostly short so that most operations find
/// what they name.
fn path() -> impl Strategy<Value = String> {
    let name = || prop::sample::select(vec!["a", "b", "c"]);
    prop_oneof![
        4 => name().prop_map(str::to_string),
        4 => (name(), name()).prop_map(|(a, b)| format!("{a}/{b}")),
        1 => (name(), name(), name()).prop_map(|(a, b, c)| format!("{a}/{b}/{c}")),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    let offset = prop_oneof![0u64..20_000, 270_000u64..290_000];
    prop_oneof![
        4 => path().prop_map(Op::Create),
        2 => path().prop_map(Op::Mkdir),
        1 => (path(), 1usize..120).prop_map(|(p, l)| Op::Symlink(p, l)),
        6 => (path(), offset, 0usize..6000, any::<u8>()).prop_map(|(p, o, l, s)| Op::Write(p, o, l, s)),
        2 => (path(), 0u64..30_000).prop_map(|(p, l)| Op::Truncate(p, l)),
        2 => path().prop_map(Op::Unlink),
        1 => path().prop_map(Op::Rmdir),
        2 => (path(), path()).prop_map(|(a, b)| Op::Rename(a, b)),
        2 => (path(), path()).prop_map(|(a, b)| Op::Link(a, b)),
        1 => Just(Op::Remount),
    ]
}

fn check(block_size: u32, ops: &[Op]) {
    let mut disk = MemDisk::zeroed(8 << 20);
    let sectors = disk.sectors();
    let options = FormatOptions {
        block_size,
        inode_size: 128,
        now: now(),
        ..FormatOptions::default()
    };
    ext2::format(&mut disk, sectors, &options).unwrap();
    let mut fs = Ext2::mount(disk).unwrap();
    fs.set_now(now());
    let mut model = Model::default();
    for (i, op) in ops.iter().enumerate() {
        if let Op::Remount = op {
            fs = Ext2::mount(fs.unmount().unwrap()).unwrap();
            fs.set_now(now());
            continue;
        }
        let expected = model.apply(op);
        let got = run(&mut fs, op);
        assert_eq!(got, expected, "op {i}: {op:?}");
        if std::env::var_os("EXT2_MODEL_TRACE").is_some() && got.is_ok() {
            eprintln!("done: {op:?}");
        }
        if let Op::Write(p, ..) | Op::Truncate(p, _) = op
            && got.is_ok()
        {
            let ino = resolve(&mut fs, p).unwrap();
            let MNode::File(id) = model.paths[p] else {
                unreachable!()
            };
            assert!(
                read_all(&mut fs, ino) == model.files[&id],
                "op {i}: contents of {p}"
            );
        }
    }
    let tree = model.tree();
    verify_with_crate(&mut fs, &tree);
    let disk = fs.unmount().unwrap();
    assert_fsck_clean(&disk.data, "after random operations");
    let mut fs = Ext2::mount(disk).unwrap();
    verify_with_crate(&mut fs, &tree);
    let _ = ROOT_INO;
}

/// Found by the random operations: two symbolic links with the same target are two nodes,
/// and renaming one over the other replaces it.
#[test]
fn a_symlink_renamed_over_another_with_the_same_target_replaces_it() {
    let ops = [
        Op::Symlink("a".into(), 2),
        Op::Symlink("c".into(), 2),
        Op::Rename("c".into(), "a".into()),
        Op::Unlink("c".into()),
        Op::Link("a".into(), "b".into()),
        Op::Rename("b".into(), "a".into()),
    ];
    check(1024, &ops);
    check(4096, &ops);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn random_operations_1k(ops in prop::collection::vec(op(), 1..60)) {
        check(1024, &ops);
    }

    #[test]
    fn random_operations_4k(ops in prop::collection::vec(op(), 1..60)) {
        check(4096, &ops);
    }
}
